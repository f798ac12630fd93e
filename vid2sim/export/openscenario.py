"""OpenSCENARIO 1.2 (``scenario.xosc``) and OpenDRIVE 1.8 (``road.xodr``) export with
scenariogeneration.

OpenDRIVE: the roads with their cross-sections (:mod:`vid2sim.export.opendrive`, reference
lines fitted by :mod:`vid2sim.export.refline`).

OpenSCENARIO. The ego (``Ego``) and every actor (``actor_<id>``) are Vehicles (a tram of the
``tram`` category) whose reference point is the centre of the bounding box's footprint (the
scenario's positions). Init teleports each to its first logged pose with its logged speed;
one event per vehicle starts at simulation time 0 with a FollowTrajectoryAction along a
Polyline of timed WorldPositions (absolute timing, ``time = t - t0`` where ``t0`` is the
ego's first time, so OpenSCENARIO's clock starts with the ego log). Actors whose log starts
later or ends earlier are made invisible (VisibilityAction) outside their span. The
storyboard stops at the ego log's end.

Output is reproducible: header dates come from ``SOURCE_DATE_EPOCH`` (default the Unix epoch)
and numbers are written with 12 significant digits.

scenariogeneration ships the OpenSCENARIO 1.2 schema.
"""

from __future__ import annotations

import functools
import math
import os
import shutil
import tempfile
import xml.etree.ElementTree as ET
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from vid2sim.core.scenario import Scenario, Trajectory
from vid2sim.export.assemble import straight_road_for
from vid2sim.export.opendrive import build_opendrive, set_header_bounds
from vid2sim.export.refline import (  # noqa: F401 - the fit's names, as before the split
    FIT_TOLERANCE_M,
    KNOT_SPACING_M,
    ReferenceLine,
    _ClothoidModel,
    fit_reference_line,
)

_SINGLE_SAMPLE_HOLD_S = 0.1  # how long a once-seen vehicle's polyline lasts [s]

XOSC_NAME = "scenario.xosc"
XODR_NAME = "road.xodr"

#: The variation parameters of ``vid2sim test-policy --vary`` every scenario.xosc declares,
#: with their neutral values (the recorded scenario): ``lead_decel`` scale of the lead's
#: deceleration, ``gap`` scale of the initial gap to the lead, ``ego_speed`` offset of the
#: ego's speed [m/s], ``cut_in`` time shift of the cut-in's lateral motion [s]
#: (:mod:`vid2sim.adas.variations`).
VARIATION_PARAMETERS = {"lead_decel": 1.0, "gap": 1.0, "ego_speed": 0.0, "cut_in": 0.0}
#: Values a parameter's physics allows, as OpenSCENARIO value constraints (rule, value):
#: a deceleration scale below 0 would turn braking into accelerating, a gap scale of 0 or
#: less puts the vehicles into each other.
PARAMETER_CONSTRAINTS = {"lead_decel": ("greaterOrEqual", 0.0), "gap": ("greaterThan", 0.0)}


# --------------------------------------------------------------------------- OpenSCENARIO


def _vehicle(name: str, category: str, length_m: float, width_m: float, height_m: float):
    from scenariogeneration import xosc

    kind = {"truck": xosc.VehicleCategory.truck, "bus": xosc.VehicleCategory.bus,
            "motorcycle": xosc.VehicleCategory.motorbike,
            "tram": xosc.VehicleCategory.tram}.get(category, xosc.VehicleCategory.car)
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

    ``ParameterDeclarations`` declare the variation parameters of ``vid2sim test-policy
    --vary`` (:data:`VARIATION_PARAMETERS`) at their neutral values, or at ``parameters``'
    (type double), e.g. a variant's, so the file records which variant it is. The recorded
    trajectories are polylines: the file written for a variant (``test-policy
    --write-scenarios``) holds the varied trajectories; overriding a parameter in a player
    does not re-shape them (OpenSCENARIO cannot express "scale this polyline's braking").
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
    return xosc.Scenario(
        "vid2sim replay", "vid2sim", _declarations(parameters), entities, storyboard,
        xosc.RoadNetwork(roadfile=road_file), xosc.Catalog(), osc_minor_version=2)


def _declarations(parameters: dict[str, float] | None):
    """``ParameterDeclarations``: the variation parameters (:data:`VARIATION_PARAMETERS`) at
    their neutral values or the variant's, then any other given parameter; doubles, with
    :data:`PARAMETER_CONSTRAINTS`."""
    from scenariogeneration import xosc

    values = dict(VARIATION_PARAMETERS, **(parameters or {}))
    declarations = xosc.ParameterDeclarations()
    for name, value in values.items():
        param = xosc.Parameter(name, xosc.ParameterType.double, format(float(value), ".12g"))
        if name in PARAMETER_CONSTRAINTS:
            rule, bound = PARAMETER_CONSTRAINTS[name]
            group = xosc.ValueConstraintGroup()
            group.add_value_constraint(xosc.ValueConstraint(getattr(xosc.Rule, rule),
                                                            format(bound, ".12g")))
            param.add_value_constraint_group(group)
        declarations.add_parameter(param)
    return declarations


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
    set_header_bounds(odr_root, scenario.roads or [straight_road_for(scenario.ego)])
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
