"""Per-stage timing of the session loop: fixed-size ring buffers, summaries on request."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

STAGES = ("capture", "follow", "simulate", "render", "output")


class StageClock:
    """Milliseconds per stage for the last `capacity` frames, plus the two latencies.

    `input_to_pose` runs from the start of the frame's capture stage (the newest input is read)
    to the end of its simulate stage (the puppets hold the pose that input asked for);
    `input_to_output` runs to the end of the output stage (the frame is written / sent)."""

    def __init__(self, capacity: int = 4096):
        self.capacity = capacity
        self.samples = {name: np.zeros(capacity) for name in
                        STAGES + ("total", "input_to_pose", "input_to_output")}
        self.counts = {name: 0 for name in self.samples}

    def add(self, name: str, milliseconds: float) -> None:
        count = self.counts[name]
        self.samples[name][count % self.capacity] = milliseconds
        self.counts[name] = count + 1

    def values(self, name: str) -> np.ndarray:
        count = self.counts[name]
        return self.samples[name][:min(count, self.capacity)]

    def summary(self) -> dict[str, dict[str, float]]:
        """{name: {"median", "p90", "mean", "max", "count"}} in milliseconds."""
        out = {}
        for name in self.samples:
            values = self.values(name)
            if values.size == 0:
                out[name] = {"median": 0.0, "p90": 0.0, "mean": 0.0, "max": 0.0, "count": 0}
                continue
            out[name] = {"median": float(np.median(values)),
                         "p90": float(np.percentile(values, 90)),
                         "mean": float(values.mean()), "max": float(values.max()),
                         "count": int(self.counts[name])}
        return out


@dataclass
class SessionReport:
    """What a session did: frames, drops, per-stage timing, latency and source events."""
    frames: int = 0
    rendered: int = 0
    dropped: int = 0
    fps: int = 25
    wall_seconds: float = 0.0
    stages: dict = field(default_factory=dict)
    events: list = field(default_factory=list)
    performers: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"frames": self.frames, "rendered": self.rendered, "dropped": self.dropped,
                "fps": self.fps, "wall_seconds": self.wall_seconds, "stages": self.stages,
                "events": list(self.events), "performers": self.performers}

    def format(self) -> str:
        """A plain-text table for the terminal."""
        lines = [f"{self.frames} frames at {self.fps} fps ({self.frames / self.fps:.1f} s of "
                 f"performance) in {self.wall_seconds:.1f} s wall; {self.rendered} rendered, "
                 f"{self.dropped} dropped"]
        lines.append(f"  {'stage':<16}{'median ms':>10}{'p90 ms':>9}{'mean ms':>9}")
        for name in STAGES + ("total", "input_to_pose", "input_to_output"):
            row = self.stages.get(name)
            if not row or not row["count"]:
                continue
            label = name.replace("_", " ")
            lines.append(f"  {label:<16}{row['median']:>10.2f}{row['p90']:>9.2f}"
                         f"{row['mean']:>9.2f}")
        for name, info in self.performers.items():
            lines.append(f"  performer {name}: {info['status']}, {info['frames']} input frames, "
                         f"actions followed: {', '.join(info['actions_seen']) or 'none'}")
        for event in self.events:
            lines.append(f"  t={event['t']:.2f}s {event['performer']}: {event['message']}")
        return "\n".join(lines)
