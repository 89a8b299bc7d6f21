"""Keyframe baking (Animatron's player): keep the simulated mesh only at key times and play back
by blending linearly between the two stored shapes around the time asked for.

Key times are where a pin movement starts or ends (the motion's channel key times: between two
keys of a linearly interpolated channel the pin moves uniformly) and, in between, enough extra
keys that no two are more than `max_interval` apart. Playback then costs one blend of two
(N, 2) arrays per frame instead of a simulation; what it loses is reported by `deviation`: the
distance between blended and simulated vertices, in pixels.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def key_times(motion, *, duration: float, max_interval: float) -> np.ndarray:
    """(K,) float [s], increasing, from 0 to duration: every channel key time in range, then
    evenly spread extra keys wherever two are more than max_interval apart."""
    if not (max_interval > 0 and math.isfinite(max_interval)):
        raise ValueError(f"max_interval must be a positive time [s], got {max_interval}")
    times = {0.0, float(duration)}
    for name in motion.channel_names:
        channel_times, _ = motion.keys(name)
        times.update(float(t) for t in channel_times if 0.0 <= t <= duration)
    anchors = np.array(sorted(times))
    keys = [anchors[0]]
    for start, end in zip(anchors[:-1], anchors[1:]):
        pieces = max(1, math.ceil((end - start) / max_interval - 1e-9))
        keys.extend(start + (end - start) * np.arange(1, pieces + 1) / pieces)
    return np.array(keys)


@dataclass(frozen=True)
class BakedMotion:
    """Stored shapes and how to blend them.

    times : (K,) float [s] increasing; shapes : (K, N, 2) float [px];
    deviation_max, deviation_mean : float [px] over the frames it was baked from (the
    largest / mean vertex distance between blended playback and the simulation), or NaN.
    """

    times: np.ndarray
    shapes: np.ndarray
    deviation_max: float = math.nan
    deviation_mean: float = math.nan

    @property
    def duration(self) -> float:
        return float(self.times[-1])

    @property
    def key_count(self) -> int:
        return len(self.times)

    def shape_at(self, t: float, out: np.ndarray | None = None) -> np.ndarray:
        """(N, 2) float [px]: the blend at time t [s] (clamped to the baked range)."""
        times = self.times
        t = min(max(float(t), times[0]), times[-1])
        upper = int(np.searchsorted(times, t, side="right"))
        upper = min(max(upper, 1), len(times) - 1)
        lower = upper - 1
        alpha = (t - times[lower]) / (times[upper] - times[lower])
        if out is None:
            out = np.empty(self.shapes.shape[1:])
        np.multiply(self.shapes[lower], 1.0 - alpha, out=out)
        out += alpha * self.shapes[upper]
        return out

    def deviation(self, frame_times: np.ndarray, simulated: np.ndarray) -> np.ndarray:
        """(T,) float [px]: largest vertex distance between playback and simulated shapes
        (T, N, 2) at frame_times (T,) [s]."""
        out = np.empty(len(frame_times))
        buffer = np.empty(self.shapes.shape[1:])
        for i, t in enumerate(frame_times):
            self.shape_at(t, buffer)
            out[i] = np.sqrt(((buffer - simulated[i]) ** 2).sum(1)).max()
        return out

    def save(self, path) -> None:
        """Write as .npz (times, shapes); no pickled objects."""
        np.savez_compressed(path, times=self.times, shapes=self.shapes,
                            deviation=np.array([self.deviation_max, self.deviation_mean]))

    @classmethod
    def load(cls, path) -> "BakedMotion":
        with np.load(path, allow_pickle=False) as data:
            missing = {"times", "shapes"} - set(data.files)
            if missing:
                raise ValueError(f"{path} is not a baked motion: it lacks {sorted(missing)}")
            deviation = data["deviation"] if "deviation" in data.files else [math.nan] * 2
            return cls(times=data["times"], shapes=data["shapes"],
                       deviation_max=float(deviation[0]), deviation_mean=float(deviation[1]))


def bake_motion(motion, shapes: np.ndarray, *, fps: float, max_interval: float) -> BakedMotion:
    """Keep key shapes out of a frame-by-frame simulation.

    shapes : (T, N, 2) float [px] simulated at t = i / fps. Key times are snapped to frames.
    """
    frame_count = len(shapes)
    duration = (frame_count - 1) / fps
    wanted = key_times(motion, duration=duration, max_interval=max_interval)
    frames = np.unique(np.clip(np.round(wanted * fps).astype(int), 0, frame_count - 1))
    baked = BakedMotion(times=frames / fps, shapes=shapes[frames].copy())
    errors = baked.deviation(np.arange(frame_count) / fps, shapes)
    return BakedMotion(times=baked.times, shapes=baked.shapes,
                       deviation_max=float(errors.max()), deviation_mean=float(errors.mean()))
