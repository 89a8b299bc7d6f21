"""Per-stage timing of the session loop: fixed-size ring buffers, summaries on request."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

LOOP_STAGES = ("capture", "follow", "simulate", "send")   # the loop, every frame
PICTURE_STAGES = ("render", "output")                      # the render worker, per picture
STAGES = LOOP_STAGES + PICTURE_STAGES
LATENCIES = ("total", "input_to_pose")


class StageClock:
    """Milliseconds per stage for the last `capacity` frames, plus the loop's total and latency.

    `total` is the loop's own work per frame (capture to send); `input_to_pose` runs from the
    start of the frame's capture stage (its input is read) to the end of its simulate stage (the
    puppets hold the pose that input asked for). "render" (draw + compose) and "output" (video,
    PNG, preview writes) are the render worker's, per picture, in its own thread. Other names
    get a ring of their first `add` (the loop adds "simulate CHARACTER", each character's part
    of the simulate stage)."""

    def __init__(self, capacity: int = 4096):
        self.capacity = capacity
        self.samples = {name: np.zeros(capacity) for name in STAGES + LATENCIES}
        self.counts = {name: 0 for name in self.samples}

    def track(self, name: str) -> None:
        """Keep a ring for `name` (before the first `add` from another thread)."""
        if name not in self.samples:
            self.samples[name] = np.zeros(self.capacity)
            self.counts[name] = 0

    def add(self, name: str, milliseconds: float) -> None:
        count = self.counts.get(name)
        if count is None:
            self.track(name)
            count = 0
        self.samples[name][count % self.capacity] = milliseconds
        self.counts[name] = count + 1

    def values(self, name: str) -> np.ndarray:
        count = self.counts[name]
        return self.samples[name][:min(count, self.capacity)]

    def summary(self) -> dict[str, dict[str, float]]:
        """{name: {"median", "p90", "mean", "max", "count"}} in milliseconds."""
        out = {}
        for name in list(self.samples):
            values = self.values(name).copy()    # the worker thread may be adding
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
    """What a session did: frames, pictures, whether it kept real time, per-stage timing,
    latency and source events.

    rendered + dropped = frames when there were pictures (a dropped picture is written as a
    repeat); late_frames: live frames that started more than a period late (they were still
    followed and simulated, the next ones caught up); slipped [s]: time the session clock gave
    up because the loop was more than its limit behind (that input was not followed)."""
    frames: int = 0
    rendered: int = 0
    dropped: int = 0
    fps: int = 25
    wall_seconds: float = 0.0
    stages: dict = field(default_factory=dict)
    events: list = field(default_factory=list)
    performers: dict = field(default_factory=dict)
    mode: str = "replay"
    pictures: bool = False
    late_frames: int = 0
    max_late: float = 0.0
    slipped: float = 0.0
    slips: int = 0
    warmup_seconds: float = 0.0

    def to_dict(self) -> dict:
        return {"frames": self.frames, "rendered": self.rendered, "dropped": self.dropped,
                "fps": self.fps, "wall_seconds": self.wall_seconds, "stages": self.stages,
                "events": list(self.events), "performers": self.performers, "mode": self.mode,
                "late_frames": self.late_frames, "max_late": self.max_late,
                "slipped": self.slipped, "slips": self.slips,
                "warmup_seconds": self.warmup_seconds}

    def verdict(self) -> str:
        """One plain sentence: did the show keep its rate, and what was dropped."""
        if self.mode == "replay":
            return "replay: every frame followed, simulated and drawn"
        budget = 1e3 / self.fps
        loop = self.stages.get("total", {}).get("median", 0.0)
        if self.slipped > 0:
            return (f"NOT real time: the simulation could not keep {self.fps} fps (its loop "
                    f"takes {loop:.1f} ms of the {budget:.0f} ms a frame has); the clock "
                    f"slipped {self.slipped:.2f} s in {self.slips} place(s) and that input was "
                    f"not followed")
        caught = (f"; {self.late_frames} frames started late (at most "
                  f"{1e3 * self.max_late:.0f} ms) and the loop caught up"
                  if self.late_frames else "")
        return f"real time: every frame followed and simulated{caught}"

    def format(self) -> str:
        """A plain-text table for the terminal."""
        drops = ""
        if self.pictures and self.frames:
            drops = (f"; {self.rendered} pictures drawn, {self.dropped} dropped "
                     f"({100.0 * self.dropped / self.frames:.1f} %, repeated in the video)")
        lines = [f"{self.frames} frames at {self.fps} fps ({self.frames / self.fps:.1f} s of "
                 f"performance) in {self.wall_seconds:.1f} s wall, {self.mode}{drops}",
                 f"  {self.verdict()}"]
        lines.append(f"  {'stage':<16}{'median ms':>10}{'p90 ms':>9}{'mean ms':>9}")
        for name in STAGES + LATENCIES:
            row = self.stages.get(name)
            if not row or not row["count"]:
                continue
            label = {"total": "loop total", "render": "render (worker)",
                     "output": "output (worker)"}.get(name, name.replace("_", " "))
            lines.append(f"  {label:<16}{row['median']:>10.2f}{row['p90']:>9.2f}"
                         f"{row['mean']:>9.2f}")
            if name == "simulate":
                for part, row in self.stages.items():
                    if part.startswith("simulate ") and row["count"]:
                        lines.append(f"    {part[9:]:<14}{row['median']:>10.2f}"
                                     f"{row['p90']:>9.2f}{row['mean']:>9.2f}")
        for name, info in self.performers.items():
            status = info["status"]
            if status not in ("ok", "ended") and info.get("message"):
                status = f"{status} ({info['message']})"
            latency = info.get("latency")
            timing = f", input latency {1e3 * latency:.0f} ms" if latency else ""
            outliers = info.get("outliers", 0)
            absurd = (f", {outliers} frames far outside the recorded range (no action)"
                      if outliers else "")
            lines.append(f"  performer {name}: {status}, {info['frames']} input frames"
                         f"{timing}{absurd}, actions followed: "
                         f"{', '.join(info['actions_seen']) or 'none'}")
        for event in self.events:
            lines.append(f"  t={event['t']:.2f}s {event['performer']}: {event['message']}")
        return "\n".join(lines)
