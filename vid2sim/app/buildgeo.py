"""The build's first stages: the ego trajectory, the road, the camera (file or calibrated).

Order, since each needs the one before: the calibration cues (when the camera is not
given whole, or the GPS clock is unknown), the GPS-video time sync (no ``--gps-offset``
and no clock in the GPS file), the smoothed ego trajectory, the road (its lane width is
the calibration's prior where the map tags it), then the camera itself. Without GPS the
ego's speed comes from the road's flow at the camera's height (a camera-relative scenario
with a real speed) unless ``--ego-speed`` is given.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from vid2sim.app import calibrate as cal
from vid2sim.app import selfcal
from vid2sim.app.gpsroad import match_road
from vid2sim.app.inputs import Inputs
from vid2sim.app.loaders import load_trace, smooth_trace
from vid2sim.app.settings import Settings
from vid2sim.base.errors import InconsistentInputError
from vid2sim.core.camera import Camera
from vid2sim.core.records import EgoTrack, GpsTrace, Note, Origin, RoadResult, VideoInfo

#: The road's flow must give the ego's speed on at least this share of the flow pairs (and
#: this many) for a camera-only scenario to drive at it.
MIN_SPEED_COVERAGE = 0.5
MIN_SPEED_PAIRS = 5
#: A visual speed below this [m/s] while the tracked scene moves more than this a pair
#: [px] (median over pairs) means the road's flow stuck to edges, not that the ego stood.
STILL_SPEED_MPS = 1.0
MOVING_SCENE_PX = 2.0
#: Smoothing of the visual ego speed for a camera-only scenario [s]: a pair's speed
#: scatters by 3-5 %; a car's speed changes little within a second.
VISUAL_SPEED_WINDOW_S = 1.0


@dataclass(slots=True)
class GeoStage:
    """What the first stages hand on."""

    inputs: Inputs
    ego: EgoTrack
    camera: Camera
    choice: selfcal.CameraChoice
    trace: GpsTrace | None = None
    road_result: RoadResult | None = None
    roads: list = field(default_factory=list)
    ego_noise_m: float | None = None


def ego_without_gps(duration_s: float, speed_mps: float, rate_hz: float) -> EgoTrack:
    """A straight ego drive heading east from the ENU origin at a constant speed.

    Used when no GPS trace is given: the scenario is then camera-relative (speed 0) or
    relative to an assumed constant ego speed.
    """
    return ego_from_speeds(duration_s, rate_hz, np.array([0.0]), np.array([float(speed_mps)]))


def ego_from_speeds(duration_s: float, rate_hz: float, t_s: np.ndarray, speed_mps: np.ndarray
                    ) -> EgoTrack:
    """A straight ego drive heading east with a speed profile (held beyond its ends)."""
    n = max(2, int(np.floor(duration_s * rate_hz)) + 1)
    t = np.arange(n) / rate_hz
    v = np.interp(t, t_s, speed_mps) if len(t_s) > 1 else np.full(n, float(speed_mps[0]))
    x = np.concatenate(([0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))))
    zeros = np.zeros(n)
    return EgoTrack(origin=Origin(0.0, 0.0, 0.0), t_s=t, x_m=x, y_m=zeros.copy(),
                    heading_rad=zeros.copy(), speed_mps=v, lat_deg=zeros.copy(),
                    lon_deg=zeros.copy())


def smoothed_speeds(speeds: list[tuple[float, float]], window_s: float = VISUAL_SPEED_WINDOW_S
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Visual speeds (t, v) smoothed by a running median within ``window_s`` (a few pairs
    whose road was hidden read wild)."""
    if not speeds:
        return np.zeros(0), np.zeros(0)
    t = np.array([s[0] for s in speeds])
    v = np.array([s[1] for s in speeds])
    order = np.argsort(t)
    t, v = t[order], v[order]
    out = np.array([np.median(v[np.abs(t - ti) <= window_s / 2]) for ti in t])
    return t, np.maximum(out, 0.0)


def clip_ego_to_video(ego: EgoTrack, duration_s: float) -> tuple[EgoTrack, list[str]]:
    """Keep the ego samples inside the video's time span [0, duration] (scenario clock)."""
    warnings: list[str] = []
    keep = (ego.t_s >= -1e-9) & (ego.t_s <= duration_s + 1e-9)
    if keep.sum() < 2:
        raise InconsistentInputError(
            None, f"the GPS trace does not overlap the video (GPS covers "
            f"{ego.t_s[0]:.1f}..{ego.t_s[-1]:.1f} s of video time, the video "
            f"0..{duration_s:.1f} s)", "check the clocks or pass --gps-offset")
    if ego.t_s[0] > 0.5:
        warnings.append(f"GPS starts {ego.t_s[0]:.1f} s after the first video frame")
    if ego.t_s[-1] < duration_s - 0.5:
        warnings.append(f"GPS ends {duration_s - ego.t_s[-1]:.1f} s before the last video frame")
    if keep.all():
        return ego, warnings
    fields_ = {name: (getattr(ego, name)[keep] if isinstance(getattr(ego, name), np.ndarray)
                      else getattr(ego, name)) for name in EgoTrack.__slots__}
    return EgoTrack(**fields_), warnings


def _gps_stages(stages, inputs: Inputs, settings: Settings, info: VideoInfo,
                choice: selfcal.CameraChoice, duration_s: float, notes: list) -> GeoStage:
    trace = stages.run("read GPS", load_trace, inputs)
    if selfcal.needs_sync(inputs, trace):
        inputs, trace = stages.run("GPS-video time sync", selfcal.sync_offset, choice,
                                   inputs, info, settings, trace)
    ego, trace_stats = stages.run("smooth ego trajectory", smooth_trace, trace, inputs,
                                  settings)
    notes.extend(trace_stats.warnings)
    notes.extend(Note.assumption(a) for a in trace_stats.assumptions)
    ego, clip_warnings = clip_ego_to_video(ego, duration_s)
    notes.extend(clip_warnings)
    road_result = stages.run("road and map matching", match_road, trace, ego, inputs,
                             settings)
    notes.extend(road_result.warnings)
    lane_prior = cal.lane_prior_from_roads(list(road_result.roads), road_result.source,
                                           cal.calibration_config(settings))
    camera = stages.run("calibrate camera", selfcal.finish_camera, choice, inputs, info,
                        settings, trace, ego, lane_prior)
    return GeoStage(inputs=inputs, ego=ego, camera=camera, choice=choice, trace=trace,
                    road_result=road_result, roads=list(road_result.roads),
                    ego_noise_m=trace_stats.noise_m)


def _camera_only(stages, inputs: Inputs, settings: Settings, info: VideoInfo,
                 choice: selfcal.CameraChoice, duration_s: float, notes: list) -> GeoStage:
    camera = stages.run("calibrate camera", selfcal.finish_camera, choice, inputs, info,
                        settings)
    speed = inputs.ego_speed_mps
    if speed == 0 and choice.cues is not None:
        pairs = len(choice.cues.pairs)
        t, v = smoothed_speeds(selfcal.visual_ego_speeds(choice, info, settings))
        scene_px = float(np.median([np.median(np.linalg.norm(p.points_b - p.points_a, axis=1))
                                    for p in choice.cues.pairs if len(p.points_a)] or [0.0]))
        still = len(t) and np.median(v) < STILL_SPEED_MPS and scene_px > MOVING_SCENE_PX
        if len(t) < max(MIN_SPEED_PAIRS, MIN_SPEED_COVERAGE * pairs) or still:
            notes.append(Note.warning(
                f"no GPS: the road's flow gave the ego's speed on {len(t)} of {pairs} frame "
                + ("pairs, but near zero while the scene moves "
                   f"{scene_px:.1f} px a pair" if still else "pairs, too few to trust")
                + " (too little road texture): the scenario is camera-relative (pass "
                "--ego-speed)"))
        else:
            notes.append(Note.assumption(
                f"no GPS: the ego drives a straight road heading east from an arbitrary "
                f"origin (lat 0, lon 0) at the speed the road's flow gives at the camera's "
                f"{camera.height_m:.2f} m height (median {np.median(v):.1f} m/s, "
                f"{v.min():.1f}-{v.max():.1f} m/s)"))
            return GeoStage(inputs, ego_from_speeds(duration_s, settings.rate_hz, t, v),
                            camera, choice)
    notes.append(Note.assumption(
        f"no GPS: the ego drives a straight road heading east at {speed:g} m/s from an "
        "arbitrary origin (lat 0, lon 0)" + (" (a camera-relative scenario)" if speed == 0
                                            else "")))
    return GeoStage(inputs, ego_without_gps(duration_s, speed, settings.rate_hz), camera,
                    choice)


def geo_and_camera(stages, inputs: Inputs, settings: Settings, info: VideoInfo,
                   choice: selfcal.CameraChoice, duration_s: float, notes: list) -> GeoStage:
    """The ego, road and camera of a build (see the module docstring); ``notes`` extended."""
    # (the time sync measures the cues itself, once it knows the GPS file has no clock)
    visual_speed = inputs.gps is None and inputs.ego_speed_mps == 0
    if choice.calibrating or visual_speed:
        stages.run("calibration cues", selfcal.measure_cues_for, choice, inputs, info, settings)
    if inputs.gps is not None:
        geo = _gps_stages(stages, inputs, settings, info, choice, duration_s, notes)
    else:
        geo = _camera_only(stages, inputs, settings, info, choice, duration_s, notes)
    notes.extend(choice.notes)
    return geo
