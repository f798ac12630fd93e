"""Variations around a recorded scenario (parameter exploration for ``test-policy --vary``).

Parameters (name, meaning, neutral value):

- ``lead_decel``: scale of the lead vehicle's deceleration (1 = as recorded). From the time it
  first leads the ego, where its 1 s-averaged acceleration is negative, that is multiplied by
  the scale; speed and position along its own path follow (a vehicle that stops stays stopped
  until it accelerates again). Before it leads (a cut-in's approach) nothing changes;
- ``gap``: scale of the initial gap to the lead (1 = as recorded), the bumper-to-bumper gap
  when the lead is first the ego's lead; the whole lead trajectory moves along its path;
- ``ego_speed``: offset of the ego's logged speed [m/s] (0 = as recorded); the ego's log is
  re-timed along its path (this is what ``log`` replays and the recorded driver tracks; ACC's
  set speed follows);
- ``cut_in``: time shift of the cut-in's lateral motion [s] (0 = as recorded; positive:
  later, at the same longitudinal motion), measured across the ego's path;
- ``noise``: sensor noise level of the episode (:mod:`vid2sim.adas.sensor`).

The lead is the actor that is the ego's lead (see :mod:`vid2sim.export.highway`) on most steps
of the log replay; the cut-in is the actor entering the ego's path from beside it (first seen
at least 1.5 half lane widths to the side) at the smallest gap.

``--vary`` syntax: comma-separated ``NAME=VALUES`` with VALUES one of ``V`` (a single value),
``LO:HI:N`` (N evenly spaced values from LO to HI), ``V1/V2/...`` (a list) or, with
``--samples N``, ``LO:HI`` (uniform random). Without ``--samples`` the variations are the
grid of all combinations; with it, N seeded random draws (each parameter uniform in its range
or one of its values). Example: ``lead_decel=0.5:1.5:5,gap=0.6:1.2:5`` (25 variations).

A physically impossible variant (a negative ego speed, vehicles overlapping at the start or
where a varied vehicle appears) is not simulated: :func:`apply_variation` returns the reason.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, replace

import numpy as np
from shapely.geometry import Polygon

from vid2sim.base.errors import FormatError, ImpossibleValueError
from vid2sim.core.scenario import Scenario, Trajectory
from vid2sim.export.highway import ReplayEnv, enu_to_hw, hw_to_enu
from vid2sim.export.openscenario import VARIATION_PARAMETERS

PARAMETERS = {
    "lead_decel": ("scale of the lead's deceleration", VARIATION_PARAMETERS["lead_decel"], None),
    "gap": ("scale of the initial gap to the lead", VARIATION_PARAMETERS["gap"], None),
    "ego_speed": ("offset of the ego's speed [m/s]", VARIATION_PARAMETERS["ego_speed"], None),
    "cut_in": ("time shift of the cut-in [s]", VARIATION_PARAMETERS["cut_in"], None),
    "noise": ("sensor noise level", 0.0, 0.0),
}
"""name -> (meaning, neutral value, smallest value --vary accepts or None); the neutral values
are the ones every exported scenario.xosc declares. Values that make a
variant physically impossible (a gap scale of 0 or less, a negative deceleration scale) are
accepted and their variants skipped with the reason, so that a grid can span them."""
MAX_GRID = 10_000
"""Most variations one --vary grid may hold (a typo like 0:1:1000000 fails fast)."""
SMOOTH_WINDOW_S = 1.0
"""Averaging window of the acceleration whose negative part ``lead_decel`` scales [s]."""
OVERLAP_AREA_M2 = 0.01
"""Footprint intersection above which two vehicles overlap [m^2]."""
_HINT = "e.g. --vary lead_decel=0.5:1.5:5,gap=0.6:1.2:5 (names: " + ", ".join(PARAMETERS) + ")"


# --------------------------------------------------------------------------- the --vary spec


@dataclass(frozen=True)
class Axis:
    """One varied parameter: listed values, or a range for random sampling."""

    name: str
    values: tuple[float, ...] | None
    low: float
    high: float


def _number(text: str, name: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise FormatError(None, f"--vary {name}: {text!r} is not a number", _HINT) from None
    if not math.isfinite(value):
        raise ImpossibleValueError(None, f"--vary {name}: {text!r} is not a finite number", _HINT)
    return value


def parse_vary(text: str, random: bool = False) -> tuple[Axis, ...]:
    """Parse ``--vary``; ``random`` (``--samples`` given) allows ``LO:HI`` ranges.

    Raises :class:`InputError` for unknown names, malformed values, repeated names, values
    below a parameter's minimum, and grids that are empty or too large.
    """
    axes: list[Axis] = []
    if not text or not text.strip():
        raise FormatError(None, "--vary is empty", _HINT)
    for item in text.split(","):
        name, eq, values = item.strip().partition("=")
        name = name.strip()
        if not eq or not name or not values.strip():
            raise FormatError(None, f"--vary: {item.strip()!r} is not NAME=VALUES", _HINT)
        if name not in PARAMETERS:
            raise FormatError(None, f"--vary: unknown parameter {name!r}", _HINT)
        if any(a.name == name for a in axes):
            raise FormatError(None, f"--vary: {name} is given twice", _HINT)
        axes.append(_parse_axis(name, values.strip(), random))
    size = math.prod(len(a.values) for a in axes if a.values is not None)
    if not random and size > MAX_GRID:
        raise ImpossibleValueError(
            None, f"--vary: the grid has {size} variations (at most {MAX_GRID})",
            "use fewer points or --samples N")
    return tuple(axes)


def _parse_axis(name: str, text: str, random: bool) -> Axis:
    minimum = PARAMETERS[name][2]
    if ":" in text:
        parts = text.split(":")
        if len(parts) not in (2, 3):
            raise FormatError(None, f"--vary {name}: {text!r} is not LO:HI:N", _HINT)
        lo, hi = _number(parts[0], name), _number(parts[1], name)
        if hi < lo:
            raise ImpossibleValueError(
                None, f"--vary {name}: {text!r} runs backwards (LO > HI)", _HINT)
        if len(parts) == 3:
            try:
                n = int(parts[2])
            except ValueError:
                raise FormatError(None, f"--vary {name}: the count {parts[2]!r} is not a whole "
                                  "number", _HINT) from None
            if n < 1 or (n == 1 and hi != lo):
                raise ImpossibleValueError(
                    None, f"--vary {name}: {text!r} needs a count of at least 2 "
                    "(or LO = HI with 1)", _HINT)
            # 10 significant digits: 0.6 + 2 * 0.15 is 0.9, not 0.8999999999999999
            values = tuple(float(f"{v:.10g}") for v in np.linspace(lo, hi, n))
        elif random:
            values = None
        else:
            raise FormatError(None, f"--vary {name}: {text!r} has no number of grid points",
                              "write LO:HI:N, or give --samples N to draw at random")
    else:
        values = tuple(_number(v, name) for v in text.split("/"))
        lo, hi = min(values), max(values)
    if minimum is not None and lo < minimum:
        raise ImpossibleValueError(
            None, f"--vary {name}: values must be at least {minimum:g}, got {lo:g}",
            _HINT)
    return Axis(name, values, lo, hi)


def variations(axes: tuple[Axis, ...], samples: int | None = None,
               seed: int = 0) -> list[dict[str, float]]:
    """The variations to run: the grid of ``axes`` or ``samples`` seeded random draws."""
    if samples is None:
        grids = [a.values for a in axes]
        return [dict(zip((a.name for a in axes), combo, strict=True))
                for combo in itertools.product(*grids)]
    rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, 0xA7E5])
    out = []
    for _ in range(samples):
        draw = {}
        for a in axes:
            draw[a.name] = (float(rng.choice(a.values)) if a.values is not None
                            else float(rng.uniform(a.low, a.high)))
        out.append(draw)
    return out


def label(values: dict[str, float]) -> str:
    """``name=value`` pairs for reports (``recorded`` without any)."""
    if not values:
        return "recorded"
    return " ".join(f"{k}={v:.4g}" for k, v in values.items())


# --------------------------------------------------------------------------- the log's roles


@dataclass(frozen=True)
class LogRoles:
    """Who plays which part in the recorded scenario, from a replay of its log."""

    lead_id: str | None
    lead_first_t_s: float | None
    lead_first_gap_m: float | None
    cut_in_id: str | None
    cut_in_t_s: float | None


def find_roles(scenario: Scenario) -> LogRoles:
    """Replay the log and name the lead (most steps as the ego's lead) and the cut-in."""
    env = ReplayEnv(scenario, ego_mode="log")
    env.reset(seed=0)
    steps: dict[str, int] = {}
    first: dict[str, tuple[float, float]] = {}
    beside: set[str] = set()
    entries: list[tuple[float, str, float]] = []
    in_path_before: dict[str, bool] = {}
    action = np.zeros(1, np.float32)
    for k in range(env.n_steps + 1):
        if k:
            env.step(action)
        traffic = env.traffic()
        half = env.path.width_at(0.0) / 2.0
        if traffic.lead is not None:
            lead = traffic.lead
            steps[lead.id] = steps.get(lead.id, 0) + 1
            first.setdefault(lead.id, (float(env.t_s), float(lead.gap_m)))
        for o in traffic.objects:
            if o.along_m <= 0:
                continue
            if not o.in_path and abs(o.lateral_m) >= 1.5 * half:
                beside.add(o.id)
            if o.in_path and not in_path_before.get(o.id, True) and o.id in beside:
                entries.append((o.gap_m, o.id, float(env.t_s)))
            in_path_before[o.id] = o.in_path
    env.close()
    lead_id = max(steps, key=lambda i: (steps[i], -first[i][0])) if steps else None
    cut = min(entries) if entries else None
    return LogRoles(lead_id, first[lead_id][0] if lead_id else None,
                    first[lead_id][1] if lead_id else None,
                    cut[1] if cut else None, cut[2] if cut else None)


# --------------------------------------------------------------------------- transforms


def _arc_length(traj: Trajectory) -> np.ndarray:
    return np.r_[0.0, np.cumsum(np.hypot(np.diff(traj.x), np.diff(traj.y)))]


def _move_along(traj: Trajectory, s_new: np.ndarray, speed: np.ndarray) -> Trajectory:
    """The trajectory's own path evaluated at arc lengths ``s_new`` (straight beyond its ends,
    along its first/last heading), with new speeds."""
    s = _arc_length(traj)
    heading = np.unwrap(traj.heading)
    if s[-1] < 1e-6:  # a vehicle that never moved: its path is its heading
        x = traj.x[0] + (s_new - s[0]) * math.cos(heading[0])
        y = traj.y[0] + (s_new - s[0]) * math.sin(heading[0])
        return Trajectory(traj.t, x, y, traj.heading, speed)
    x = np.interp(s_new, s, traj.x)
    y = np.interp(s_new, s, traj.y)
    h = np.interp(s_new, s, heading)
    before, after = s_new < 0.0, s_new > s[-1]
    x[before] = traj.x[0] + s_new[before] * math.cos(heading[0])
    y[before] = traj.y[0] + s_new[before] * math.sin(heading[0])
    x[after] = traj.x[-1] + (s_new[after] - s[-1]) * math.cos(heading[-1])
    y[after] = traj.y[-1] + (s_new[after] - s[-1]) * math.sin(heading[-1])
    return Trajectory(traj.t, x, y, h, speed)


def scale_deceleration(traj: Trajectory, scale: float, from_t_s: float = -math.inf
                       ) -> Trajectory:
    """``lead_decel``: the negative part of the smoothed acceleration times ``scale``, from
    ``from_t_s`` on."""
    if len(traj) < 3 or scale == 1.0:
        return traj
    t, v = traj.t, traj.speed
    accel = np.gradient(v, t)
    dt = float(np.median(np.diff(t)))
    half = max(round(SMOOTH_WINDOW_S / dt / 2), 1)
    kernel = np.ones(2 * half + 1) / (2 * half + 1)
    smooth = np.convolve(np.pad(accel, half, mode="edge"), kernel, mode="valid")
    extra_accel = (scale - 1.0) * np.minimum(smooth, 0.0) * (t >= from_t_s - 1e-9)
    # added to the logged speed (not re-integrated), so nothing changes before from_t_s; a
    # vehicle braked to a stop stays stopped until its logged speed outgrows the deficit
    extra_speed = np.r_[0.0, np.cumsum(0.5 * (extra_accel[1:] + extra_accel[:-1]) * np.diff(t))]
    speed = np.maximum(v + extra_speed, 0.0)
    extra = np.r_[0.0, np.cumsum(0.5 * ((speed - v)[1:] + (speed - v)[:-1]) * np.diff(t))]
    return _move_along(traj, _arc_length(traj) + extra, speed)


def shift_along(traj: Trajectory, shift_m: float) -> Trajectory:
    """The whole trajectory ``shift_m`` further along its own path."""
    return _move_along(traj, _arc_length(traj) + shift_m, traj.speed)


def offset_speed(traj: Trajectory, offset_mps: float) -> Trajectory:
    """``ego_speed``: speeds plus ``offset_mps``, positions re-timed along the same path."""
    t = traj.t
    return _move_along(traj, _arc_length(traj) + offset_mps * (t - t[0]),
                       traj.speed + offset_mps)


def shift_cut_in(traj: Trajectory, shift_s: float, path) -> Trajectory:
    """``cut_in``: the offset across the ego's path ``path`` (a lane of the replay, highway-env
    frame) delayed by ``shift_s``; the motion along the path is kept."""
    if shift_s == 0.0 or len(traj) < 2:
        return traj
    xh, yh = enu_to_hw(traj.x, traj.y)
    s, lat = np.array([path.local_coordinates(np.array(p)) for p in zip(xh, yh, strict=True)]).T
    lat_new = np.interp(traj.t - shift_s, traj.t, lat)
    pts = np.array([path.position(si, li) for si, li in zip(s, lat_new, strict=True)])
    x, y = hw_to_enu(pts[:, 0], pts[:, 1])
    ds = np.gradient(s, traj.t)
    # the heading turns by the change of the lateral motion's angle to the path
    turn = (np.arctan2(-np.gradient(lat_new, traj.t), np.maximum(np.abs(ds), 0.1))
            - np.arctan2(-np.gradient(lat, traj.t), np.maximum(np.abs(ds), 0.1)))
    return Trajectory(traj.t, x, y, np.unwrap(traj.heading) + turn, traj.speed)


def _footprint(x, y, h, length, width) -> Polygon:
    c, s = math.cos(h), math.sin(h)
    pts = [(x + c * dx - s * dy, y + s * dx + c * dy)
           for dx, dy in ((length / 2, width / 2), (-length / 2, width / 2),
                          (-length / 2, -width / 2), (length / 2, -width / 2))]
    return Polygon(pts)


def overlaps_at(scenario: Scenario, t_s: float,
                involving: set[str] | None = None) -> tuple[str, str] | None:
    """The first pair of vehicles whose footprints overlap at ``t_s`` (only pairs with one of
    ``involving``, when given), or None."""
    boxes = []
    for vid, length, width, traj in [("ego", scenario.ego.length_m, scenario.ego.width_m,
                                      scenario.ego.trajectory)] + [
            (a.id, a.length_m, a.width_m, a.trajectory) for a in scenario.actors]:
        if not traj.t[0] - 1e-9 <= t_s <= traj.t[-1] + 1e-9:
            continue
        st = traj.state_at(t_s)
        boxes.append((vid, _footprint(float(st["x"]), float(st["y"]), float(st["heading"]),
                                      length, width)))
    for (a, pa), (b, pb) in itertools.combinations(boxes, 2):
        if involving is not None and a not in involving and b not in involving:
            continue
        if pa.intersection(pb).area > OVERLAP_AREA_M2:
            return a, b
    return None


def apply_variation(scenario: Scenario, values: dict[str, float], roles: LogRoles,
                    path=None) -> tuple[Scenario | None, str]:
    """The scenario with ``values`` applied, or ``(None, reason)`` for a variant that cannot
    be simulated. ``path`` is the ego's path lane (for ``cut_in``; from a log-mode env)."""
    actors = {a.id: a for a in scenario.actors}
    changed: list[str] = []
    ego = scenario.ego
    notes = []

    def need(role_id, what):
        if role_id is None or role_id not in actors:
            raise _Skip(f"no {what} in the log")

    try:
        for name, value in values.items():
            neutral = PARAMETERS[name][1]
            if name == "noise" or value == neutral:
                continue
            if name == "lead_decel":
                if value < 0.0:
                    raise _Skip(f"negative deceleration scale ({value:g}: braking would "
                                "become accelerating)")
                need(roles.lead_id, "lead vehicle")
                a = actors[roles.lead_id]
                actors[a.id] = replace(a, trajectory=scale_deceleration(
                    a.trajectory, value, roles.lead_first_t_s))
                changed.append(a.id)
                notes.append(f"lead {a.id} deceleration x{value:g}")
            elif name == "gap":
                need(roles.lead_id, "lead vehicle")
                a = actors[roles.lead_id]
                shift = (value - 1.0) * roles.lead_first_gap_m
                if value * roles.lead_first_gap_m <= 0.0:
                    raise _Skip(f"initial gap of {value * roles.lead_first_gap_m:.1f} m (scale "
                                f"{value:g})")
                actors[a.id] = replace(a, trajectory=shift_along(a.trajectory, shift))
                changed.append(a.id)
                notes.append(f"lead {a.id} initial gap x{value:g}")
            elif name == "ego_speed":
                lowest = float(np.min(ego.trajectory.speed)) + value
                if lowest < 0.0:
                    raise _Skip(f"negative ego speed ({lowest:.1f} m/s with offset {value:g})")
                ego = replace(ego, trajectory=offset_speed(ego.trajectory, value))
                changed.append("ego")
                notes.append(f"ego speed {value:+g} m/s")
            elif name == "cut_in":
                need(roles.cut_in_id, "cut-in")
                a = actors[roles.cut_in_id]
                actors[a.id] = replace(a, trajectory=shift_cut_in(a.trajectory, value, path))
                changed.append(a.id)
                notes.append(f"cut-in {a.id} {value:+g} s")
    except _Skip as skip:
        return None, str(skip)
    source = replace(scenario.source, assumptions=[*scenario.source.assumptions,
                                                   "variation: " + "; ".join(notes)]
                     ) if notes else scenario.source
    varied = replace(scenario, ego=ego, actors=[actors[a.id] for a in scenario.actors],
                     source=source)
    moved = set(changed)
    times = [float(varied.ego.trajectory.t[0])] + [
        float(actors[i].trajectory.t[0]) for i in dict.fromkeys(changed) if i != "ego"]
    for t in times:
        pair = overlaps_at(varied, t, moved)
        if pair is not None:
            return None, f"vehicles {pair[0]} and {pair[1]} overlap at t={t:.1f} s"
    return varied, ""


class _Skip(Exception):
    pass
