"""Cut-in clips with exact truth: a real car pasted into KITTI raw 0001 moving from the lane
left of the ego lane into it (:mod:`vid2sim.samples.composite` does the pasting).

The truth of a cut-in is the moment the car's centre crosses the ego lane's left boundary,
so the clip needs the ego lane itself. It is measured on the drive *without* the car: the lane
markings of every frame (:class:`~vid2sim.detect.lanes.markings.LaneMarkingDetector`, the
lane track with the OXTS speed) give the lane's middle beside the camera, which placed in
the world with the OXTS poses is fitted by one cubic across the ~100 m drive (as
:func:`vid2sim.evaluate.lane_checks.world_line_scatter` checks it: 0.07 m RMS scatter at 10 m,
``python benchmarks/bench_lanes.py --kitti``). The car's lateral position is then set *in
that lane's coordinates*: from the middle of the lane to the left (+1 lane width) to the
middle of the ego lane along a minimum-jerk profile, so the true crossing of the boundary
(+half a lane width) is known exactly, and converted to the camera frame of every frame for
the paste.

Honest limits: the pasted image is the car's rear view also where a real car 3.5 m to the
side would show a little of its flank (at 15 m that is 13 deg off axis), and the left
"lane" of this residential street is the oncoming side of the road.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from vid2sim.core.camera import Camera
from vid2sim.detect.lanes.markings import LaneMarkingDetector
from vid2sim.detect.lanes.track import lane_track
from vid2sim.detect.video import iter_frames
from vid2sim.evaluate.lane_checks import kitti_camera_poses
from vid2sim.samples.composite import DEFAULT_FPS, LeadTruth, lead_profile

#: A lane change takes 3-6 s from start to end (Toledo and Zohar 2007, NGSIM); drawn in this
#: range [s].
CUT_IN_DURATION_S = (3.0, 5.0)
#: The cut-in's range to the car's rear stays within these bounds [m]: nearer than the
#: events' 30 m reach (vid2sim.export.events.EventConfig.max_range_m), farther than the
#: bonnet.
CUT_IN_RANGE_M = (10.0, 26.0)


@dataclass(frozen=True)
class EgoLaneWorld:
    """The ego lane's middle in the world (ENU about the first OXTS fix) as a cubic across the
    drive's chord, plus the camera's pose per frame and the measured lane width [m]."""

    coef: np.ndarray
    origin_xy: np.ndarray
    chord: np.ndarray
    poses: dict[str, np.ndarray]
    lane_width_m: float

    def centre_in_frame(self, frame: int, x_m: float) -> float:
        """The lane middle's lateral position [m, positive left] ``x_m`` ahead of the camera's
        ground point in frame ``frame``'s vehicle frame."""
        x0, y0 = self.poses["x_m"][frame], self.poses["y_m"][frame]
        h = self.poses["yaw_rad"][frame]
        normal = np.array([-self.chord[1], self.chord[0]])
        # the curve sampled densely around the frame, moved into its vehicle frame
        a0 = float((np.array([x0, y0]) - self.origin_xy) @ self.chord)
        along = a0 + np.linspace(-10.0, x_m + 30.0, 400)
        across = np.polyval(self.coef, along)
        wx = self.origin_xy[0] + along * self.chord[0] + across * normal[0]
        wy = self.origin_xy[1] + along * self.chord[1] + across * normal[1]
        c, s = np.cos(h), np.sin(h)
        vx = (wx - x0) * c + (wy - y0) * s
        vy = -(wx - x0) * s + (wy - y0) * c
        return float(np.interp(x_m, vx, vy))


def measure_ego_lane(raw_dir: Path, camera: Camera, n_frames: int,
                     fps: float = DEFAULT_FPS) -> EgoLaneWorld:
    """The ego lane of the clean drive (module docstring)."""
    raw_dir = Path(raw_dir)
    det = LaneMarkingDetector(camera)
    obs = [det.measure(f.image_bgr, f.index, f.index / fps)
           for f in iter_frames(raw_dir / "video.mp4") if f.index < n_frames]
    poses = kitti_camera_poses(raw_dir)
    track = lane_track(obs, speed_mps=poses["speed_mps"][:len(obs)])
    middle = -np.asarray(track.ego_offset_m, dtype=float)  # the lane's middle beside the camera
    x, y, h = (poses[k][:len(middle)] for k in ("x_m", "y_m", "yaw_rad"))
    wx, wy = x - np.sin(h) * middle, y + np.cos(h) * middle
    origin = np.array([x[0], y[0]])
    chord = np.array([x[-1] - x[0], y[-1] - y[0]])
    chord /= np.linalg.norm(chord)
    normal = np.array([-chord[1], chord[0]])
    along = (wx - origin[0]) * chord[0] + (wy - origin[1]) * chord[1]
    across = (wx - origin[0]) * normal[0] + (wy - origin[1]) * normal[1]
    ok = np.isfinite(across)
    if ok.sum() < 10:
        raise RuntimeError(f"the ego lane was measured in only {ok.sum()} frames of {raw_dir}")
    return EgoLaneWorld(np.polyfit(along[ok], across[ok], 3), origin, chord, poses,
                        float(np.nanmedian(track.lane_width_m)))


def min_jerk(tau: np.ndarray) -> np.ndarray:
    """The minimum-jerk step from 0 to 1 over ``tau`` in [0, 1] (clipped outside)."""
    u = np.clip(tau, 0.0, 1.0)
    return u ** 3 * (10.0 - 15.0 * u + 6.0 * u ** 2)


@dataclass(frozen=True)
class CutInTruth:
    """A cut-in trajectory: the pasted car's truth (camera frame) and, in the ego lane's
    coordinates, its centre's offset from the lane middle ``lane_offset_m`` [m, positive
    left]; ``t_enter_s`` the moment its centre crosses the left boundary (offset = half the
    lane width) [s]."""

    lead: LeadTruth
    lane_offset_m: np.ndarray
    t_enter_s: float
    lane_width_m: float


def cut_in_truth(seed: int, lane: EgoLaneWorld, n_frames: int, car_length_m: float,
                 fps: float = DEFAULT_FPS) -> CutInTruth:
    """A seeded cut-in: the range of a :func:`composite.lead_profile` within
    :data:`CUT_IN_RANGE_M`; across, from the middle of the lane to the left to the ego lane's
    middle along :func:`min_jerk` over :data:`CUT_IN_DURATION_S`, starting 2-4 s into the
    clip."""
    rng = np.random.default_rng(10_000 + seed)
    base = lead_profile(seed, n_frames, fps, range_bounds_m=CUT_IN_RANGE_M, max_speed_mps=4.0)
    duration = float(rng.uniform(*CUT_IN_DURATION_S))
    start = float(rng.uniform(2.0, 4.0))
    w = lane.lane_width_m
    offset = w * (1.0 - min_jerk((base.t_s - start) / duration))
    # the centre crosses +w/2 at the step's middle (min_jerk(0.5) = 0.5)
    t_enter = start + 0.5 * duration
    lateral = np.array([lane.centre_in_frame(i, float(base.range_m[i]) + car_length_m / 2.0)
                        for i in range(n_frames)]) + offset
    lead = LeadTruth(t_s=base.t_s, range_m=base.range_m, lateral_m=lateral,
                     range_rate_mps=base.range_rate_mps, rel_accel_mps2=base.rel_accel_mps2,
                     seed=seed)
    return CutInTruth(lead, offset, t_enter, w)


def in_lane(truth: LeadTruth, lane: EgoLaneWorld) -> LeadTruth:
    """The profile's lateral offsets taken from the middle of the drive's real ego lane (as
    measured without the car, :func:`measure_ego_lane`) at the car's rear, instead of from the
    camera's axis: a car pasted along the axis is 1.8 m RMS off the lane at 40 m on KITTI raw
    0001, and the lane markings then put it in the next lane."""
    middle = np.array([lane.centre_in_frame(i, float(r)) for i, r in enumerate(truth.range_m)])
    return replace(truth, lateral_m=truth.lateral_m + middle)
