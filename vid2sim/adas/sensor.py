"""What a forward camera would report to a driving function: objects and lane markings.

:class:`CameraSensor` wraps ``vid2sim/Replay-v0`` and replaces its observation with the
camera-style array below, built from the environment's exact traffic snapshot
(:meth:`ReplayEnv.traffic`). With ``SensorConfig(level=0)`` (the default) the array is exact:
every vehicle ahead, no latency, no dropouts. With ``level > 0`` the camera of the scenario
(focal length ``fx`` [px], mounting height ``height_m``, image width) limits what is seen
(horizontal field of view, :attr:`SensorConfig.max_range_m`) and the measurements carry a
monocular error model, seeded by ``reset(seed=...)``:

- range: the ground cue (bottom edge of the box on the road plane at image row
  ``v = cy + f H / Z``) turns a row error ``sigma_px`` into ``sigma_Z = Z^2 sigma_px / (f H)``;
- lateral offset: the column error and the range error, ``sigma_Y^2 = (Z sigma_px / f)^2 +
  (Y sigma_Z / Z)^2``;
- range rate: ``sigma = a + b Z`` (a tracker's estimate);
- latency: objects and lane markings are reported as they were ``latency_s`` ago;
- dropouts: each object (and the lane model) is missed on a frame with a probability; the
  tracker coasts a missed object at its last range rate for up to ``hold_s``.

The lane-marking measurement is a lane model fitted to marking points at ``lane_near_m`` and
``lane_far_m`` ahead on both sides, each with a column error ``lane_sigma_px``; the fit's
offset, heading and curvature errors follow from the two points' errors (least squares of a
line through two points, averaged over the two markings).

Target selection (which object is the lead) is the environment's: the nearest vehicle ahead
whose centre is within half a lane width of the ego's path; only its measurements are noisy.

Observation, ``float32`` array of shape ``(2 + OBJECT_ROWS, 6)`` (zeros where absent):

- row 0, the ego (vehicle bus, exact, no latency): ``t_s, speed_mps, accel_mps2, odometer_m,
  yaw_rate_radps, lane`` (lane numbered from the right, 0 = rightmost);
- row 1, the lane model: ``valid, lateral_offset_m, heading_error_rad, curvature_per_m,
  lane_width_m, 0`` (offset of the ego's centre from the lane centre and curvature positive
  LEFT, heading error counter-clockwise positive);
- row 2, the lead: ``present, range_m, range_rate_mps, lateral_m, lane_offset, width_m``;
- rows 3.., other vehicles ahead by range, same columns.

``range_m`` is bumper to bumper along the ego's path (the ego's front to the object's rear),
``range_rate_mps`` its rate (negative when closing), ``lateral_m`` the object's centre from
the ego's path (positive left), ``lane_offset`` lanes left of the ego's lane.
:func:`read_frame` turns the array into a :class:`CameraFrame`.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import gymnasium
import numpy as np

from vid2sim.core.camera import DEFAULT_HEIGHT_M, DEFAULT_HFOV_DEG

OBJECT_ROWS = 8
"""Object rows of the observation: the lead and the 7 nearest other vehicles ahead."""
COLUMNS = 6
EXACT_RANGE_M = 200.0
"""How far ahead the exact (level 0) observation lists vehicles [m]."""
_EGO_ROW, _LANE_ROW, _LEAD_ROW = 0, 1, 2


@dataclass(frozen=True)
class SensorConfig:
    """The camera error model; every noise figure is for ``level = 1`` and scales with the
    level (0 = exact and unrestricted)."""

    level: float = 0.0
    sigma_px: float = 2.0
    """Row/column error of a vehicle box's bottom edge and centre [px]: on KITTI's camera
    (f 721 px, H 1.65 m) it gives a 3.4 % range error at 20 m, between a single YOLOX box's
    jitter and the 5.1 % median the project measured as tracks on KITTI labels (README,
    ``benchmarks/bench_ranging.py --kitti``)."""
    range_rate_sigma_mps: float = 0.1
    range_rate_sigma_per_m: float = 0.016
    """Range-rate error ``a + b Z`` [m/s, 1/s]: a line through the project's measured lead
    range-rate RMSE, 0.5 m/s below 40 m and 0.95 m/s to 70 m (``benchmarks/bench_ranging.py``)."""
    latency_s: float = 0.1
    """Age of object and lane reports [s]: one frame at 10 fps (not scaled by the level)."""
    dropout: float = 0.05
    """Probability of missing an object on a frame (at most 0.5 at any level)."""
    hold_s: float = 0.3
    """How long the tracker coasts a missed object or lane model [s]."""
    max_range_m: float = 100.0
    """Farthest object reported [m] (a car is ~14 px wide at 100 m with f = 720 px)."""
    lane_sigma_px: float = 3.0
    """Column error of a lane-marking point [px] (thin, worn paint: worse than a box edge)."""
    lane_near_m: float = 5.0
    lane_far_m: float = 20.0
    """Distances of the marking points of the lane model [m]."""
    lane_dropout: float = 0.05
    """Probability of losing the lane model on a frame (at most 0.5 at any level)."""

    @property
    def on(self) -> bool:
        return self.level > 0.0


@dataclass(frozen=True)
class CameraGeometry:
    """The scenario camera's numbers the error model needs."""

    focal_px: float = 640.0
    height_m: float = 1.3
    hfov_rad: float = math.pi / 2

    @classmethod
    def from_record(cls, camera: dict) -> CameraGeometry:
        """From a scenario's camera record; missing fields fall back to the project's default
        dash-cam (90 deg horizontal field of view, 1.3 m high, 1280 px wide)."""
        width = float(camera.get("image_width", 1280))
        focal = float(camera.get("fx", (width / 2) / math.tan(math.radians(DEFAULT_HFOV_DEG) / 2)))
        height = float(camera.get("height_m", DEFAULT_HEIGHT_M))
        if not (focal > 0 and height > 0 and width > 0):
            raise ValueError(f"camera needs positive fx, height_m and width, got {camera}")
        return cls(focal, height, 2.0 * math.atan(width / (2.0 * focal)))


def range_sigma_m(range_m, cfg: SensorConfig, cam: CameraGeometry):
    """Monocular ground-cue range error [m] at camera distance ``range_m``:
    ``Z^2 sigma_px / (f H)``, scaled by the level."""
    z = np.asarray(range_m, float)
    return cfg.level * z * z * cfg.sigma_px / (cam.focal_px * cam.height_m)


def lateral_sigma_m(range_m, lateral_m, cfg: SensorConfig, cam: CameraGeometry):
    """Lateral offset error [m]: the column error at range Z plus the range error's share."""
    z = np.maximum(np.asarray(range_m, float), 0.1)
    col = cfg.level * z * cfg.sigma_px / cam.focal_px
    return np.hypot(col, np.asarray(lateral_m, float) * range_sigma_m(z, cfg, cam) / z)


def range_rate_sigma_mps(range_m, cfg: SensorConfig):
    """Range-rate error [m/s] at camera distance ``range_m``."""
    return cfg.level * (cfg.range_rate_sigma_mps + cfg.range_rate_sigma_per_m
                        * np.asarray(range_m, float))


def lane_model_sigmas(cfg: SensorConfig, cam: CameraGeometry) -> tuple[float, float, float]:
    """Errors of the lane model's offset [m], heading [rad] and curvature [1/m].

    A marking point at distance d has a lateral error ``d sigma_px / f``. The line through the
    points at d1 and d2 has an intercept error ``sqrt(d2^2 s1^2 + d1^2 s2^2) / (d2 - d1)`` and a
    slope error ``sqrt(s1^2 + s2^2) / (d2 - d1)``; the curvature, from the far point's
    deviation ``kappa d2^2 / 2``, ``2 s2 / d2^2``. Both markings average: divide by sqrt 2.
    """
    d1, d2 = cfg.lane_near_m, cfg.lane_far_m
    s1 = cfg.level * d1 * cfg.lane_sigma_px / cam.focal_px
    s2 = cfg.level * d2 * cfg.lane_sigma_px / cam.focal_px
    offset = math.sqrt((d2 * s1) ** 2 + (d1 * s2) ** 2) / (d2 - d1) / math.sqrt(2)
    heading = math.hypot(s1, s2) / (d2 - d1) / math.sqrt(2)
    curvature = 2.0 * s2 / d2**2 / math.sqrt(2)
    return offset, heading, curvature


# --------------------------------------------------------------------------- parsed frames


@dataclass(frozen=True, slots=True)
class Track:
    """One reported object."""

    range_m: float
    range_rate_mps: float
    lateral_m: float
    lane_offset: int
    width_m: float


@dataclass(frozen=True, slots=True)
class LaneModel:
    lateral_offset_m: float
    heading_error_rad: float
    curvature_per_m: float
    lane_width_m: float


@dataclass(frozen=True, slots=True)
class CameraFrame:
    """A camera observation, parsed (see the module docstring for the array)."""

    t_s: float
    speed_mps: float
    accel_mps2: float
    odometer_m: float
    yaw_rate_radps: float
    ego_lane: int
    lane: LaneModel | None
    lead: Track | None
    objects: tuple[Track, ...]


def _track(row: np.ndarray) -> Track | None:
    if row[0] < 0.5:
        return None
    return Track(float(row[1]), float(row[2]), float(row[3]), round(float(row[4])),
                 float(row[5]))


def read_frame(obs: np.ndarray) -> CameraFrame:
    """Parse a :class:`CameraSensor` observation."""
    obs = np.asarray(obs, dtype=float)
    ego, lane = obs[_EGO_ROW], obs[_LANE_ROW]
    lane_model = (LaneModel(float(lane[1]), float(lane[2]), float(lane[3]), float(lane[4]))
                  if lane[0] >= 0.5 else None)
    others = tuple(t for t in (_track(r) for r in obs[_LEAD_ROW + 1:]) if t is not None)
    return CameraFrame(float(ego[0]), float(ego[1]), float(ego[2]), float(ego[3]),
                       float(ego[4]), round(float(ego[5])), lane_model,
                       _track(obs[_LEAD_ROW]), others)


# --------------------------------------------------------------------------- the wrapper


@dataclass(slots=True)
class _Held:
    row: np.ndarray
    age_s: float


class CameraSensor(gymnasium.Wrapper):
    """``vid2sim/Replay-v0`` seen through a camera (see the module docstring).

    Parameters
    ----------
    env : gymnasium.Env
        A ``vid2sim/Replay-v0`` environment (or a wrapper around one).
    config : SensorConfig
        The error model and its level (0: exact).
    camera : CameraGeometry, optional
        Default: from the scenario's camera record.
    """

    def __init__(self, env: gymnasium.Env, config: SensorConfig | None = None,
                 camera: CameraGeometry | None = None):
        super().__init__(env)
        self.config = config or SensorConfig()
        sim = env.unwrapped
        sim.observe_kinematics = False  # replaced by this observation: not computed
        self.camera = camera or CameraGeometry.from_record(sim.scenario.camera)
        self.observation_space = gymnasium.spaces.Box(
            -np.inf, np.inf, (2 + OBJECT_ROWS, COLUMNS), np.float32)
        self._step_s = 1.0 / sim.config["policy_frequency"]
        self._rng = np.random.default_rng()
        self._history: deque = deque()
        self._held: dict[str, _Held] = {}
        self._lane_held: _Held | None = None

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        _, info = self.env.reset(seed=seed, options=options)
        # the sensor's own stream, derived from the episode seed (None: fresh entropy)
        self._rng = np.random.default_rng(None if seed is None else [int(seed), 0x5E45])
        self._history.clear()
        self._held, self._lane_held = {}, None
        return self._observe(), info

    def step(self, action):
        _, reward, terminated, truncated, info = self.env.step(action)
        return self._observe(), reward, terminated, truncated, info

    # ----------------------------------------------------------------- measurement

    def _observe(self) -> np.ndarray:
        sim = self.env.unwrapped
        traffic = sim.traffic()
        out = np.zeros((2 + OBJECT_ROWS, COLUMNS), dtype=np.float32)
        out[_EGO_ROW] = [sim.t_s, traffic.ego.speed_mps, sim.ego_accel_mps2, sim.odometer_m(),
                         sim.ego_yaw_rate_radps, traffic.ego.lane]
        cfg = self.config
        delay = round(cfg.latency_s / self._step_s) if cfg.on else 0
        self._history.append(traffic)
        while len(self._history) > delay + 1:
            self._history.popleft()
        seen = self._history[0]  # the snapshot `delay` steps ago (the first one until then)
        out[_LANE_ROW] = self._lane_row(seen)
        lead_row, rows = self._object_rows(seen)
        out[_LEAD_ROW] = lead_row
        for i, row in enumerate(rows[: OBJECT_ROWS - 1]):
            out[_LEAD_ROW + 1 + i] = row
        return out

    def _lane_row(self, traffic) -> np.ndarray:
        ego = traffic.ego
        truth = np.array([1.0, ego.lane_offset_m, ego.heading_error_rad,
                          ego.lane_curvature_per_m, ego.lane_width_m, 0.0])
        cfg = self.config
        if not cfg.on:
            return truth
        if self._rng.random() < min(cfg.lane_dropout * cfg.level, 0.5):
            held = self._lane_held
            if held is not None and held.age_s + self._step_s <= cfg.hold_s + 1e-9:
                held.age_s += self._step_s
                return held.row
            return np.zeros(COLUMNS)
        s_off, s_head, s_curv = lane_model_sigmas(cfg, self.camera)
        row = truth + np.array([0.0, *self._rng.normal(0.0, [s_off, s_head, s_curv]), 0.0, 0.0])
        self._lane_held = _Held(row, 0.0)
        return row

    def _object_rows(self, traffic) -> tuple[np.ndarray, list[np.ndarray]]:
        cfg, cam = self.config, self.camera
        lead_id = traffic.lead.id if traffic.lead is not None else None
        ego_half = traffic.ego.length_m / 2.0
        rows: dict[str, np.ndarray] = {}
        v_ego = traffic.ego.speed_along_mps
        for o in traffic.objects:
            if o.along_m <= 0.0:
                continue  # a forward camera: nothing behind the ego's centre
            z_cam = o.gap_m + ego_half  # the camera sits at the ego's centre (assemble stage)
            if not cfg.on:
                if o.gap_m <= EXACT_RANGE_M:
                    rows[o.id] = np.array([1.0, o.gap_m, o.speed_along_mps - v_ego,
                                           o.lateral_m, o.lane_offset, o.width_m])
                continue
            if (z_cam > cfg.max_range_m or z_cam <= 0.5
                    or abs(math.atan2(o.lateral_m, z_cam)) > cam.hfov_rad / 2):
                continue
            if self._rng.random() < min(cfg.dropout * cfg.level, 0.5):
                continue  # missed on this frame; the tracker may coast it below
            z = z_cam + self._rng.normal(0.0, float(range_sigma_m(z_cam, cfg, cam)))
            lat = o.lateral_m + self._rng.normal(
                0.0, float(lateral_sigma_m(z_cam, o.lateral_m, cfg, cam)))
            rate = (o.speed_along_mps - v_ego) + self._rng.normal(
                0.0, float(range_rate_sigma_mps(z_cam, cfg)))
            rows[o.id] = np.array([1.0, z - ego_half, rate, lat, o.lane_offset, o.width_m])
        if cfg.on:
            rows = self._track(rows)
        lead = rows.pop(lead_id, np.zeros(COLUMNS)) if lead_id is not None else np.zeros(COLUMNS)
        others = sorted(rows.values(), key=lambda r: r[1])
        return lead, others

    def _track(self, rows: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Coast objects missed on this frame for up to ``hold_s``, at their last range rate."""
        held = {}
        for key, h in self._held.items():
            if key in rows:
                continue
            age = h.age_s + self._step_s
            if age <= self.config.hold_s + 1e-9:
                row = h.row.copy()
                row[1] += row[2] * self._step_s
                held[key] = _Held(row, age)
                rows[key] = row
        for key, row in rows.items():
            if key not in held:
                held[key] = _Held(row, 0.0)
        self._held = held
        return rows
