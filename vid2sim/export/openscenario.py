"""OpenSCENARIO 1.2 (``scenario.xosc``) and OpenDRIVE 1.8 (``road.xodr``) export with
scenariogeneration.

OpenDRIVE. Each scenario road becomes one road whose reference line is the scenario centerline,
fitted as a chain of clothoids with curvature continuous and piecewise linear in ``s`` (knots
every :data:`KNOT_SPACING_M` or closer until the fit is within :data:`FIT_TOLERANCE_M` of the
centerline), each piece written as a ``line`` (zero curvature), ``arc`` (constant) or
``spiral`` (linear). The scenario's lanes all run in the travel direction, symmetric about the
centerline, so they are written as right lanes (ids -1..-n, right-hand traffic) with a
``laneOffset`` of ``n * width / 2`` that moves the centre lane to the road's left edge. The
scenario carries no heights, so elevation is one flat record (the origin's altitude is in the
header). The header's ``geoReference`` is the PROJ string of the scenario's ENU frame, so
OpenDRIVE x/y are scenario ENU metres.

OpenSCENARIO. The ego (``Ego``) and every actor (``actor_<id>``) are Vehicles whose reference
point is the centre of the bounding box's footprint (the scenario's positions). Init teleports
each to its first logged pose with its logged speed; one event per vehicle starts at simulation
time 0 with a FollowTrajectoryAction along a Polyline of timed WorldPositions (absolute timing,
``time = t - t0`` where ``t0`` is the ego's first time, so OpenSCENARIO's clock starts with the
ego log). Actors whose log starts later or ends earlier are made invisible
(VisibilityAction) outside their span. The storyboard stops at the ego log's end.

Output is reproducible: header dates come from ``SOURCE_DATE_EPOCH`` (default the Unix epoch)
and numbers are written with 12 significant digits.

scenariogeneration ships the OpenSCENARIO 1.2 schema and OpenDRIVE 1.7 schemas; the road file
uses only elements common to 1.7 and 1.8 (the ASAM checker validates it against 1.8).
"""

from __future__ import annotations

import contextlib
import functools
import itertools
import logging
import math
import os
import shutil
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

from vid2sim.enu import EnuFrame
from vid2sim.export.assemble import straight_road_for
from vid2sim.scenario import Road, Scenario, Trajectory

log = logging.getLogger(__name__)

KNOT_SPACING_M = 20.0
MIN_KNOT_SPACING_M = 4.0
FIT_TOLERANCE_M = 0.2
_SMOOTHING = 0.05  # weight of the curvature-change penalty (dimensionless)
_FINE_STEP_M = 0.25  # integration step of the curvature model [m]
_MAX_GRID = 8000  # integration steps of a fit (memory: grid x knots doubles)
_MAX_KNOTS = 500  # knots of a fit at most (long roads get a coarser minimum spacing)
_LINE_CURVATURE = 1e-5  # |k| below this (radius > 100 km) is written as a line [1/m]
_ARC_DCURVATURE = 1e-6  # |k1 - k0| below this is written as an arc [1/m]

_SINGLE_SAMPLE_HOLD_S = 0.1  # how long a once-seen vehicle's polyline lasts [s]

XOSC_NAME = "scenario.xosc"
XODR_NAME = "road.xodr"


# --------------------------------------------------------------------------- reference line fit


@dataclass(frozen=True)
class ReferenceLine:
    """A clothoid chain: start pose, knot arc lengths [m] and curvatures at the knots [1/m]."""

    x0_m: float
    y0_m: float
    heading0_rad: float
    knots_s_m: np.ndarray
    curvature_per_m: np.ndarray

    @property
    def length_m(self) -> float:
        return float(self.knots_s_m[-1])

    def sample(self, s_m: np.ndarray) -> np.ndarray:
        """(N, 2) points at arc lengths ``s_m`` (numerical integration of the curvature)."""
        return _integrate(self.x0_m, self.y0_m, self.heading0_rad, self.knots_s_m,
                          self.curvature_per_m, np.asarray(s_m, float))

    def pieces(self) -> list[tuple[str, float, float, float]]:
        """``(kind, curvature_start, curvature_end, length_m)``, one per knot interval, with
        runs of equal lines or arcs merged (repeating them is redundant information that the
        ASAM checker flags)."""
        out: list[tuple[str, float, float, float]] = []
        for i in range(len(self.knots_s_m) - 1):
            k0, k1 = float(self.curvature_per_m[i]), float(self.curvature_per_m[i + 1])
            length = float(self.knots_s_m[i + 1] - self.knots_s_m[i])
            kind = "line" if k0 == 0.0 and k1 == 0.0 else ("arc" if k0 == k1 else "spiral")
            if out and kind != "spiral" and out[-1][0] == kind and out[-1][1] == k0:
                out[-1] = (kind, k0, k1, out[-1][3] + length)
            else:
                out.append((kind, k0, k1, length))
        return out


def _integrate(x0, y0, h0, knots, kappa, s_query) -> np.ndarray:
    n = max(math.ceil(knots[-1] / _FINE_STEP_M), 1)
    s = np.linspace(0.0, knots[-1], n + 1)
    k = np.interp(s, knots, kappa)
    ds = np.diff(s)
    # heading: exact integral of the piecewise-linear curvature (trapezoid is exact here
    # when the grid contains the knots; off-knot error is O(ds^2 * dk))
    h = h0 + np.r_[0.0, np.cumsum(0.5 * (k[1:] + k[:-1]) * ds)]
    # position: midpoint heading per step (second-order accurate)
    hm = 0.5 * (h[1:] + h[:-1])
    x = x0 + np.r_[0.0, np.cumsum(np.cos(hm) * ds)]
    y = y0 + np.r_[0.0, np.cumsum(np.sin(hm) * ds)]
    return np.column_stack((np.interp(s_query, s, x), np.interp(s_query, s, y)))


def _resample(points_m: np.ndarray, step_m: float) -> tuple[np.ndarray, np.ndarray]:
    p = np.asarray(points_m, float).reshape(-1, 2)
    keep = np.r_[True, np.linalg.norm(np.diff(p, axis=0), axis=1) > 1e-6]
    p = p[keep]
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))]
    n = max(math.ceil(s[-1] / step_m), 1)
    s_new = np.linspace(0.0, s[-1], n + 1)
    return s_new, np.column_stack((np.interp(s_new, s, p[:, 0]), np.interp(s_new, s, p[:, 1])))


def _single_blas_thread():
    """One BLAS thread for the fit: the per-iteration SVD of a few-hundred-column Jacobian takes
    0.2 s on one thread but 10 s when OpenBLAS spreads it over busy cores (measured on the
    2-core CI machine)."""
    try:
        from threadpoolctl import threadpool_limits  # installed with scikit-learn
    except ImportError:  # pragma: no cover
        return contextlib.nullcontext()
    return threadpool_limits(limits=1, user_api="blas")


class _ClothoidModel:
    """Positions of a clothoid chain at given arc lengths and their exact Jacobian.

    Parameters are ``[heading0, curvature at each knot]``. On a grid of at most
    :data:`_MAX_GRID` steps the heading is the trapezoid integral of the piecewise-linear
    curvature (``h = h0 + H @ k`` with ``H`` the integrated hat functions) and positions are
    sums of ``(cos, sin)`` of the midpoint headings, as in :func:`_integrate`. The Jacobian
    follows by the chain rule (``dx/dk = -sum sin(h_mid) H_mid ds``), so a fit costs a few
    matrix products per iteration instead of one integration per parameter.
    """

    def __init__(self, x0: float, y0: float, knots: np.ndarray, s_query: np.ndarray):
        self.x0, self.y0, self.knots = x0, y0, knots
        n = int(min(max(math.ceil(knots[-1] / _FINE_STEP_M), 1), _MAX_GRID))
        s = np.linspace(0.0, knots[-1], n + 1)
        self.ds = np.diff(s)
        i = np.clip(np.searchsorted(knots, s, side="right") - 1, 0, len(knots) - 2)
        w = (s - knots[i]) / (knots[i + 1] - knots[i])
        hat = np.zeros((s.size, len(knots)))
        rows = np.arange(s.size)
        hat[rows, i] = 1.0 - w
        hat[rows, i + 1] += w
        h_of_k = np.vstack((np.zeros(len(knots)),
                            np.cumsum(0.5 * (hat[1:] + hat[:-1]) * self.ds[:, None], axis=0)))
        self.hm_of_k = 0.5 * (h_of_k[1:] + h_of_k[:-1])  # d(midpoint heading)/d(curvature)
        q = np.clip(np.searchsorted(s, s_query, side="right") - 1, 0, n - 1)
        self.q, self.qw = q, ((s_query - s[q]) / (s[q + 1] - s[q]))[:, None]

    def _at_query(self, grid: np.ndarray) -> np.ndarray:
        return (1.0 - self.qw) * grid[self.q] + self.qw * grid[self.q + 1]

    def _midpoint_heading(self, params: np.ndarray) -> np.ndarray:
        return params[0] + self.hm_of_k @ params[1:]

    def positions(self, params: np.ndarray) -> np.ndarray:
        hm = self._midpoint_heading(params)
        x = self.x0 + np.r_[0.0, np.cumsum(np.cos(hm) * self.ds)]
        y = self.y0 + np.r_[0.0, np.cumsum(np.sin(hm) * self.ds)]
        return np.column_stack((self._at_query(x[:, None])[:, 0], self._at_query(y[:, None])[:, 0]))

    def jacobian(self, params: np.ndarray) -> np.ndarray:
        """d(positions)/d(params), rows ordered like ``positions(...).ravel()``."""
        hm = self._midpoint_heading(params)
        dh = np.column_stack((np.ones_like(hm), self.hm_of_k))  # d(hm)/d(params)
        zero = np.zeros((1, dh.shape[1]))
        dx = np.vstack((zero, np.cumsum((-np.sin(hm) * self.ds)[:, None] * dh, axis=0)))
        dy = np.vstack((zero, np.cumsum((np.cos(hm) * self.ds)[:, None] * dh, axis=0)))
        jac = np.empty((2 * self.q.size, dh.shape[1]))
        jac[0::2], jac[1::2] = self._at_query(dx), self._at_query(dy)
        return jac


#: Longest piece of road fitted at once [m]. One least-squares fit costs about samples x
#: knots^2 per iteration, i.e. the cube of the length (a 6 km road: 40 s, 1.5 km: 5.6 s);
#: longer roads are fitted piece by piece, each piece starting at the previous one's end
#: pose and curvature, so the cost is linear in the length and the chain stays continuous.
FIT_PIECE_M = 500.0
# weight pinning a piece's start heading [rad] and curvature [1/m] to the previous piece's end
# (residuals are metres: 1e4 holds them to ~1e-6 while the positions are fitted)
_PIN_WEIGHT = 1e4


def fit_reference_line(centerline_m: np.ndarray, tolerance_m: float = FIT_TOLERANCE_M,
                       knot_spacing_m: float = KNOT_SPACING_M) -> tuple[ReferenceLine, float]:
    """Fit a continuous-curvature clothoid chain to a polyline.

    The start point is kept; start heading and knot curvatures are fitted by least squares on
    the positions (1 m samples; exact Jacobian), so heading errors do not accumulate into drift.
    Knot intervals holding samples farther than ``tolerance_m`` are halved and the fit repeated
    (warm-started) until all samples are within tolerance or the intervals reach
    :data:`MIN_KNOT_SPACING_M` (a sharp polyline corner cannot be followed by any curve of
    finite curvature). Roads longer than :data:`FIT_PIECE_M` are fitted in pieces of about that
    length, each continuing the chain (position, heading and curvature) where the previous one
    ends. Near-zero and near-constant curvatures are then snapped to lines and arcs if the fit
    stays within tolerance.

    Returns
    -------
    line : ReferenceLine
    max_error_m : float
        Largest distance between the fitted line and the 1 m samples of the polyline [m].
    """
    s_data, p_data = _resample(centerline_m, 1.0)
    length = float(s_data[-1])
    if length < 1e-3:
        raise ValueError("centerline has no length")
    n_pieces = max(1, round(length / FIT_PIECE_M))
    bounds = np.linspace(0, len(s_data) - 1, n_pieces + 1).round().astype(int)
    knots, kappa = [np.zeros(1)], []
    start: tuple[float, float, float, float] | None = None
    first: ReferenceLine | None = None
    for a, b in itertools.pairwise(bounds):
        piece = _fit_piece(s_data[a:b + 1] - s_data[a], p_data[a:b + 1], start, tolerance_m,
                           knot_spacing_m)
        first = first or piece
        knots.append(s_data[a] + piece.knots_s_m[1:])
        # the chain continues with the previous piece's end curvature (the new piece's first
        # knot is pinned to it)
        kappa.append(piece.curvature_per_m if start is None else piece.curvature_per_m[1:])
        end = piece.sample(np.array([piece.length_m]))[0]
        k = piece.curvature_per_m
        heading_end = piece.heading0_rad + float(np.sum(0.5 * (k[1:] + k[:-1])
                                                        * np.diff(piece.knots_s_m)))
        start = (float(end[0]), float(end[1]), heading_end, float(piece.curvature_per_m[-1]))
    line = ReferenceLine(first.x0_m, first.y0_m, first.heading0_rad, np.concatenate(knots),
                         np.concatenate(kappa))
    err = float(np.max(np.linalg.norm(line.sample(s_data) - p_data, axis=1)))
    snapped = _snap(line)
    snapped_err = float(np.max(np.linalg.norm(snapped.sample(s_data) - p_data, axis=1)))
    if snapped_err <= max(tolerance_m, err):
        return snapped, snapped_err
    return line, err


def _fit_piece(s_data: np.ndarray, p_data: np.ndarray,
               start: tuple[float, float, float, float] | None, tolerance_m: float,
               knot_spacing_m: float) -> ReferenceLine:
    """The clothoid chain of one piece (arc lengths ``s_data`` from 0, points ``p_data``).

    ``start``: None for the road's first piece (start at its first point, heading fitted),
    else the (x, y, heading, curvature) it must continue from.
    """
    length = float(s_data[-1])
    x0, y0 = p_data[0] if start is None else start[:2]
    d = np.diff(p_data, axis=0)
    seg_h = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    if start is not None:  # unwrap onto the heading the chain arrives with
        seg_h += 2 * math.pi * round((start[2] - seg_h[0]) / (2 * math.pi))
    min_spacing = max(MIN_KNOT_SPACING_M, length / _MAX_KNOTS)
    n_int = max(math.ceil(length / max(knot_spacing_m, min_spacing)), 1)
    knots = np.linspace(0.0, length, n_int + 1)
    # initial guess: curvature from the heading slope between knots
    h_knots = np.interp(knots, 0.5 * (s_data[1:] + s_data[:-1]), seg_h)
    params = np.r_[seg_h[0], np.gradient(h_knots, knots) if n_int > 1 else np.zeros(2)]
    if start is not None:
        params[0], params[1] = start[2], start[3]
    best: tuple[ReferenceLine, float] | None = None
    while True:
        model = _ClothoidModel(float(x0), float(y0), knots, s_data)
        # a weak penalty on curvature changes [1/m] * (interval length [m])^2 -> metres: damps
        # the oscillation a free fit shows on straights next to curves
        w_smooth = _SMOOTHING * np.diff(knots) ** 2
        diff_op = np.diff(np.eye(len(knots)), axis=0)
        smooth_jac = np.column_stack((np.zeros(len(knots) - 1), w_smooth[:, None] * diff_op))
        pin_jac = np.zeros((0 if start is None else 2, len(knots) + 1))
        if start is not None:
            pin_jac[0, 0] = pin_jac[1, 1] = _PIN_WEIGHT

        def residual(params, model=model, w_smooth=w_smooth):
            pin = ([] if start is None else
                   [_PIN_WEIGHT * (params[0] - start[2]), _PIN_WEIGHT * (params[1] - start[3])])
            return np.r_[(model.positions(params) - p_data).ravel(),
                         w_smooth * np.diff(params[1:]), pin]

        def jacobian(params, model=model, smooth_jac=smooth_jac, pin_jac=pin_jac):
            return np.vstack((model.jacobian(params), smooth_jac, pin_jac))

        with _single_blas_thread():
            sol = least_squares(residual, params, jac=jacobian, method="trf", x_scale="jac")
        line = ReferenceLine(float(x0), float(y0), float(sol.x[0]), knots, sol.x[1:].copy())
        dev = np.linalg.norm(line.sample(s_data) - p_data, axis=1)
        err = float(dev.max())
        if best is None or err < best[1]:
            best = (line, err)
        # refine only where the fit misses: split the knot intervals holding bad samples
        bad = np.unique(np.clip(np.searchsorted(knots, s_data[dev > tolerance_m], "right") - 1,
                                0, len(knots) - 2))
        bad = bad[np.diff(knots)[bad] / 2.0 >= min_spacing]
        if err <= tolerance_m or bad.size == 0:
            break
        new_knots = np.sort(np.r_[knots, 0.5 * (knots[bad] + knots[bad + 1])])
        params = np.r_[sol.x[0], np.interp(new_knots, knots, sol.x[1:])]  # warm start
        knots = new_knots
    return best[0]


def _snap(line: ReferenceLine) -> ReferenceLine:
    k = line.curvature_per_m.copy()
    k[np.abs(k) < _LINE_CURVATURE] = 0.0
    for i in range(len(k) - 1):
        if k[i] != 0.0 and abs(k[i + 1] - k[i]) < _ARC_DCURVATURE:
            k[i + 1] = k[i]
    return ReferenceLine(line.x0_m, line.y0_m, line.heading0_rad, line.knots_s_m, k)


# --------------------------------------------------------------------------- OpenDRIVE


def _xodr_road(road: Road, road_id: int):
    from scenariogeneration import xodr

    line, err_m = fit_reference_line(road.centerline)
    if err_m > FIT_TOLERANCE_M:
        log.warning("road %s: reference line within %.2f m of the centerline (sharp corners); "
                    "tolerance %.2f m", road.id, err_m, FIT_TOLERANCE_M)
    planview = xodr.PlanView(line.x0_m, line.y0_m, line.heading0_rad)
    for kind, k0, k1, length in line.pieces():
        if kind == "line":
            planview.add_geometry(xodr.Line(length))
        elif kind == "arc":
            planview.add_geometry(xodr.Arc(k0, length=length))
        else:
            planview.add_geometry(xodr.Spiral(k0, k1, length=length))

    centre = xodr.Lane(a=0)
    centre.add_roadmark(xodr.RoadMark(xodr.RoadMarkType.solid, 0.15))
    section = xodr.LaneSection(0, centre)
    for k in range(road.lanes):
        lane = xodr.Lane(a=road.lane_width_m)
        outer = k == road.lanes - 1
        mark = (xodr.RoadMark(xodr.RoadMarkType.solid, 0.15) if outer
                else xodr.RoadMark(xodr.RoadMarkType.broken, 0.12, length=3.0, space=9.0))
        lane.add_roadmark(mark)
        section.add_right_lane(lane)
    lanes = xodr.Lanes()
    lanes.add_lanesection(section)
    # all lanes in the travel direction: move the centre lane to the left edge
    lanes.add_laneoffset(xodr.LaneOffset(0, road.lanes * road.lane_width_m / 2.0))
    xroad = xodr.Road(road_id, planview, lanes, name=road.name or None)
    xroad.add_elevation(0, 0, 0, 0, 0)
    return xroad


def build_opendrive(scenario: Scenario, name: str = "vid2sim"):
    """The scenario's roads as a scenariogeneration ``OpenDrive`` (revision 1.8)."""
    from scenariogeneration import xodr

    roads = scenario.roads or [straight_road_for(scenario.ego)]
    odr = xodr.OpenDrive(name, revMajor="1", revMinor="8",
                         geo_reference=EnuFrame(scenario.origin).proj_string())
    for i, road in enumerate(roads, start=1):
        odr.add_road(_xodr_road(road, i))
    odr.adjust_roads_and_lanes()
    return odr


# --------------------------------------------------------------------------- OpenSCENARIO


def _vehicle(name: str, category: str, length_m: float, width_m: float, height_m: float):
    from scenariogeneration import xosc

    kind = {"truck": xosc.VehicleCategory.truck, "bus": xosc.VehicleCategory.bus,
            "motorcycle": xosc.VehicleCategory.motorbike}.get(category, xosc.VehicleCategory.car)
    # reference point = centre of the footprint; the box centre is half the height above it
    bbox = xosc.BoundingBox(width_m, length_m, height_m, 0.0, 0.0, height_m / 2.0)
    wheel_m = 0.3 * min(height_m, 2.0)
    axle_x = 0.3 * length_m
    front = xosc.Axle(0.5, wheel_m, width_m * 0.85, axle_x, wheel_m / 2)
    rear = xosc.Axle(0.0, wheel_m, width_m * 0.85, -axle_x, wheel_m / 2)
    return xosc.Vehicle(name, kind, bbox, front, rear, max_speed=70.0,
                        max_acceleration=10.0, max_deceleration=10.0)


def _polyline(traj: Trajectory, t0_s: float):
    heading = np.unwrap(traj.heading)
    times = [float(round(t - t0_s, 4)) for t in traj.t]
    x, y = traj.x.astype(float), traj.y.astype(float)
    if len(times) == 1:
        # a polyline needs two vertices: a vehicle seen once stands where it was seen
        times.append(times[0] + _SINGLE_SAMPLE_HOLD_S)
        x, y, heading = (np.repeat(a, 2) for a in (x, y, heading))
    return _log_polyline_class()(times, x, y, heading)


@functools.cache
def _log_polyline_class():
    """A scenariogeneration ``Polyline`` of WorldPositions kept as arrays (its class defined on
    first use: scenariogeneration is imported only by the exporter)."""
    from scenariogeneration import xosc

    class _LogPolyline(xosc.Polyline):
        """Writes the same XML as ``xosc.Polyline`` of ``xosc.WorldPosition(x, y, 0, h, 0, 0)``
        vertices, without a Python object per vertex (about 1.2 kB each: 44 MB for the 35,000
        vertices of a 10-minute drive, all alive while the tree is built)."""

        def __init__(self, time: list[float], x: np.ndarray, y: np.ndarray, h: np.ndarray):
            self.time, self._xyh = time, (x, y, h)
            self.positions = []  # not kept as objects; see get_element

        def get_element(self) -> ET.Element:
            shape = ET.Element("Shape")
            element = ET.SubElement(shape, "Polyline")
            for t, x, y, h in zip(self.time, *self._xyh, strict=True):
                vertex = ET.SubElement(element, "Vertex", attrib={"time": str(t)})
                position = ET.SubElement(vertex, "Position")
                ET.SubElement(position, "WorldPosition", attrib={
                    "x": str(float(x)), "y": str(float(y)), "z": "0.0", "h": str(float(h)),
                    "p": "0.0", "r": "0.0"})
            return shape

    return _LogPolyline


def _sim_time_trigger(name: str, t_s: float):
    from scenariogeneration import xosc

    return xosc.ValueTrigger(name, 0, xosc.ConditionEdge.rising,
                             xosc.SimulationTimeCondition(max(t_s, 0.0), xosc.Rule.greaterThan))


def build_openscenario(scenario: Scenario, road_file: str = XODR_NAME,
                       parameters: dict[str, float] | None = None):
    """The scenario as a scenariogeneration ``Scenario`` (OpenSCENARIO 1.2).

    ``parameters`` are declared in ``ParameterDeclarations`` (type double), e.g. the values of
    a ``vid2sim test-policy --vary`` variant, so the file records which variant it is.
    """
    from scenariogeneration import xosc

    t0 = float(scenario.ego.trajectory.t[0])
    t_end = float(scenario.ego.trajectory.t[-1]) - t0
    entities = xosc.Entities()
    init = xosc.Init()
    story = xosc.Story("replay")
    act = xosc.Act("replay_act", _sim_time_trigger("act_start", 0.0))

    vehicles = [("Ego", "car", scenario.ego.length_m, scenario.ego.width_m,
                 scenario.ego.height_m, scenario.ego.trajectory)]
    vehicles += [(f"actor_{a.id}", a.category, a.length_m, a.width_m, a.height_m, a.trajectory)
                 for a in scenario.actors]
    for name, category, length, width, height, traj in vehicles:
        entities.add_scenario_object(name, _vehicle(name, category, length, width, height))
        init.add_init_action(name, xosc.TeleportAction(xosc.WorldPosition(
            float(traj.x[0]), float(traj.y[0]), 0.0, float(traj.heading[0]), 0.0, 0.0)))
        init.add_init_action(name, xosc.AbsoluteSpeedAction(
            float(traj.speed[0]),
            xosc.TransitionDynamics(xosc.DynamicsShapes.step, xosc.DynamicsDimension.time, 0)))

        trajectory = xosc.Trajectory(f"{name}_log", False)
        trajectory.add_shape(_polyline(traj, t0))
        follow = xosc.FollowTrajectoryAction(
            trajectory, xosc.FollowingMode.position, xosc.ReferenceContext.absolute, 1, 0)
        maneuver = xosc.Maneuver(f"{name}_maneuver")
        event = xosc.Event(f"{name}_follow_log", xosc.Priority.override)
        event.add_action(f"{name}_follow_action", follow)
        event.add_trigger(_sim_time_trigger(f"{name}_follow_start", 0.0))
        maneuver.add_event(event)

        t_first, t_last = float(traj.t[0]) - t0, float(traj.t[-1]) - t0
        if name != "Ego" and t_first > 1e-6:
            # not yet seen: hidden from the start, shown when its log begins
            init.add_init_action(name, xosc.VisibilityAction(False, False, False))
            show = xosc.Event(f"{name}_appear", xosc.Priority.parallel)
            show.add_action(f"{name}_show", xosc.VisibilityAction(True, True, True))
            show.add_trigger(_sim_time_trigger(f"{name}_appear_time", t_first))
            maneuver.add_event(show)
        if name != "Ego" and t_last < t_end - 1e-6:
            hide = xosc.Event(f"{name}_disappear", xosc.Priority.parallel)
            hide.add_action(f"{name}_hide", xosc.VisibilityAction(False, False, False))
            hide.add_trigger(_sim_time_trigger(f"{name}_disappear_time", t_last))
            maneuver.add_event(hide)

        group = xosc.ManeuverGroup(f"{name}_group")
        group.add_actor(name)
        group.add_maneuver(maneuver)
        act.add_maneuver_group(group)

    story.add_act(act)
    storyboard = xosc.StoryBoard(init, _stop_trigger(t_end))
    storyboard.add_story(story)
    declarations = xosc.ParameterDeclarations()
    for name, value in (parameters or {}).items():
        declarations.add_parameter(xosc.Parameter(name, xosc.ParameterType.double,
                                                  format(float(value), ".12g")))
    return xosc.Scenario(
        "vid2sim replay", "vid2sim", declarations, entities, storyboard,
        xosc.RoadNetwork(roadfile=road_file), xosc.Catalog(), osc_minor_version=2)


def _stop_trigger(t_end_s: float):
    from scenariogeneration import xosc

    return xosc.ValueTrigger("scenario_end", 0, xosc.ConditionEdge.rising,
                             xosc.SimulationTimeCondition(t_end_s, xosc.Rule.greaterThan),
                             "stop")


# --------------------------------------------------------------------------- writing


def _tidy_numbers(root: ET.Element) -> None:
    """Write floats with 12 significant digits (``0.44999999999999996`` -> ``0.45``): far
    below a millimetre at scenario scales, and files a person can read and diff."""
    for elem in root.iter():
        for key, value in elem.attrib.items():
            if "." not in value and "e" not in value.lower():
                continue
            try:
                number = float(value)
            except ValueError:
                continue
            if math.isfinite(number):
                elem.set(key, format(number, ".12g"))


def _set_header_bounds(root: ET.Element, roads: list[Road]) -> None:
    # OpenDRIVE's header north/south/east/west bound the road data in inertial (ENU) metres;
    # scenariogeneration writes zeros.
    pts = np.vstack([r.centerline for r in roads])
    margin = max(r.lanes * r.lane_width_m for r in roads)
    header = root.find("header")
    header.set("north", format(float(pts[:, 1].max() + margin), ".6f"))
    header.set("south", format(float(pts[:, 1].min() - margin), ".6f"))
    header.set("east", format(float(pts[:, 0].max() + margin), ".6f"))
    header.set("west", format(float(pts[:, 0].min() - margin), ".6f"))


def _header_date() -> str:
    """The files' header date: SOURCE_DATE_EPOCH (the reproducible-builds convention) when set,
    else the Unix epoch, so the same scenario always gives byte-identical files."""
    epoch_s = int(os.environ.get("SOURCE_DATE_EPOCH", "0") or 0)
    return datetime.fromtimestamp(epoch_s, tz=UTC).strftime("%Y-%m-%dT%H:%M:%S")


def _write_xml(root: ET.Element, path: Path) -> None:
    header = root.find("FileHeader") if root.find("FileHeader") is not None else root.find("header")
    if header is not None:
        header.set("date", _header_date())
    _tidy_numbers(root)
    ET.indent(root, space="    ")
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)


def write_openscenario(scenario: Scenario, out_dir: Path,
                       parameters: dict[str, float] | None = None) -> tuple[Path, Path]:
    """Write ``out_dir/scenario.xosc`` (OpenSCENARIO 1.2) and ``out_dir/road.xodr``
    (OpenDRIVE 1.8), both atomically (written in a temporary folder, then renamed).
    ``parameters``: declared in the OpenSCENARIO file (see :func:`build_openscenario`).

    Returns
    -------
    xosc_path, xodr_path : Path
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    odr_root = build_opendrive(scenario).get_element()
    _set_header_bounds(odr_root, scenario.roads or [straight_road_for(scenario.ego)])
    osc_root = build_openscenario(scenario, road_file=XODR_NAME,
                                  parameters=parameters).get_element()
    tmp = Path(tempfile.mkdtemp(prefix=".vid2sim-export-", dir=out_dir))
    try:
        _write_xml(odr_root, tmp / XODR_NAME)
        _write_xml(osc_root, tmp / XOSC_NAME)
        xodr_path, xosc_path = out_dir / XODR_NAME, out_dir / XOSC_NAME
        os.replace(tmp / XODR_NAME, xodr_path)
        os.replace(tmp / XOSC_NAME, xosc_path)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return xosc_path, xodr_path
