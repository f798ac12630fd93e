"""From the fitted globals to a camera with a spread, a source and a cue per parameter."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from vid2sim.base.defaults import MAD_TO_SIGMA
from vid2sim.calib.calibconfig import CalibrationConfig
from vid2sim.calib.cues import CalibrationInput, LaneWidthPrior
from vid2sim.calib.estimate import Solution
from vid2sim.calib.groundmotion import G, P
from vid2sim.core.calibration import (
    CameraEstimate,
    LaneWidthSample,
    ParameterEstimate,
    ParameterSource,
)
from vid2sim.core.camera import Camera
from vid2sim.core.records import Note

#: Fewest frames with a measured ego lane for its width to count.
MIN_LANE_FRAMES = 5
#: Floor on the lane width's measured spread [relative]: painted lines are 0.1-0.3 m wide
#: and the ego lane's width is measured between their centres.
LANE_WIDTH_FLOOR = 0.02

#: camera-file key -> (global, to the key's unit, unit label for messages)
_KEYS = {"fx": ("log_f", None, "px"), "k1": ("k1", 1.0, ""), "k2": ("k2", 1.0, ""),
         "pitch_deg": ("pitch", math.degrees(1.0), "deg"),
         "yaw_deg": ("yaw", math.degrees(1.0), "deg"),
         "roll_deg": ("roll", math.degrees(1.0), "deg"), "height_m": ("log_h", None, "m")}
#: What a parameter needs to be seen, for the warning when it is not.
_NEEDS = {"fx": "a turn weighed against the GPS heading, or the height from lane widths",
          "k1": "long straight edges away from the image centre",
          "k2": "long straight edges near the image corners",
          "pitch_deg": "lane markings or the road's motion",
          "yaw_deg": "lane markings or the road's motion",
          "roll_deg": "the road's motion across the ego lane",
          "height_m": "GPS motion, or painted lanes of known width"}


def with_lane_widths(sol: Solution, samples: list[LaneWidthSample],
                     prior: LaneWidthPrior | None) -> tuple[Solution, str | None]:
    """The solution updated by the ego lane's width in camera heights against the prior
    width (a Gaussian update of the globals), and a line saying what it gave."""
    ratios = np.array([s.width_in_heights for s in samples
                       if np.isfinite(s.width_in_heights) and s.width_in_heights > 0])
    if prior is None or ratios.size < MIN_LANE_FRAMES or sol.problem.fixed[G["log_h"]]:
        return sol, None
    med = float(np.median(ratios))
    spread = MAD_TO_SIGMA * float(np.median(np.abs(ratios - med))) / med
    sigma = math.hypot(prior.std_m / prior.width_m,
                       spread / math.sqrt(ratios.size) + LANE_WIDTH_FLOOR)
    z = math.log(prior.width_m) - math.log(med)  # ln(height) the lanes give
    i = G["log_h"]
    s = sol.cov[i, i] + sigma ** 2
    gain = sol.cov[:, i] / s
    g = sol.g + gain * (z - sol.g[i])
    cov = sol.cov - np.outer(gain, sol.cov[i, :])
    before = sol.cov[i, i]
    sol.g, sol.cov = g, cov
    if before > 0 and cov[i, i] < 0.5 * before:
        sol.cue["log_h"] = "lane width"
        sol.observable["log_h"] = True
        if sol.cue.get("log_f") in (None, "prior", "GPS speed", "flow"):
            sol.cue["log_f"] = "lane width and road motion"
            sol.observable["log_f"] = bool(cov[G["log_f"], G["log_f"]]
                                          < 0.25 * sol.problem.prior_std[G["log_f"]] ** 2)
    return sol, (f"lane width: {med:.2f} camera heights over {ratios.size} frames, against "
                 f"{prior.width_m:.2f} +- {prior.std_m:.2f} m ({prior.source}): height "
                 f"{math.exp(z):.2f} m")


def _parameter(sol: Solution, key: str, cfg: CalibrationConfig, gps_scale: bool
               ) -> ParameterEstimate:
    name, unit, _ = _KEYS[key]
    i = G[name]
    var = max(float(sol.cov[i, i]), 0.0)
    if unit is None:  # a log parameter
        value = math.exp(sol.g[i])
        rel = math.sqrt(var + (cfg.gps_scale_std ** 2 if gps_scale else 0.0))
        std = value * rel
    else:
        value, std = float(sol.g[i]) * unit, math.sqrt(var) * unit
    if sol.problem.fixed[i]:
        return ParameterEstimate(value, float("nan"), ParameterSource.CAMERA_FILE, "camera file")
    if not sol.observable.get(name, False):
        return ParameterEstimate(value, std, ParameterSource.PRIOR, "prior")
    return ParameterEstimate(value, std, ParameterSource.ESTIMATED, sol.cue.get(name, ""))


def camera_estimate(sol: Solution, inp: CalibrationInput, cfg: CalibrationConfig,
                    lane_note: str | None = None) -> CameraEstimate:
    """The :class:`CameraEstimate` of a solution: camera, parameters, notes, speeds."""
    gps = bool(inp.motion)
    params = {k: _parameter(sol, k, cfg, gps_scale=gps and k == "height_m") for k in _KEYS}
    for key, value in inp.prior.values.items():  # held exactly as the file gives them
        if key in params:
            params[key] = replace(params[key], value=float(value))
    k2 = params["k2"]
    if k2.source is ParameterSource.ESTIMATED and not abs(k2.value) > 2.0 * k2.std:
        params["k2"] = ParameterEstimate(0.0, k2.std, ParameterSource.PRIOR, "prior")
    c = sol.problem.c
    f = params["fx"].value
    cam = Camera(image_width=inp.width_px, image_height=inp.height_px, fx=f, fy=f,
                 cx=float(c[0]), cy=float(c[1]),
                 dist=(params["k1"].value, params["k2"].value, 0.0, 0.0, 0.0),
                 height_m=params["height_m"].value, pitch_deg=params["pitch_deg"].value,
                 yaw_deg=params["yaw_deg"].value, roll_deg=params["roll_deg"].value)
    notes = _notes(params, sol, inp, cfg, lane_note)
    cam = replace(cam, assumptions=tuple(str(n) for n in notes if n.kind.value != "warning"))
    est = CameraEstimate(camera=cam, parameters=params, notes=notes,
                         frames=sorted({int(p.frame_a) for p in inp.pairs}
                                       | {int(p.frame_b) for p in inp.pairs}
                                       | {int(fl.frame) for fl in inp.lines}),
                         residual_px=sol.flow_rms_px)
    est.calibrated_from = _cues_used(sol, inp)
    est.speeds = visual_speeds(sol, params["height_m"].value)
    return est


def visual_speeds(sol: Solution, height_m: float) -> list[tuple[float, float]]:
    """(video time [s], forward speed [m/s]) of every fitted pair, at ``height_m``.

    The flow measures each pair's forward motion in camera heights; the height makes it
    metres (with GPS the fit's own motion, which GPS constrained)."""
    ps = sol.problem.pairs
    if ps is None:
        return []
    h_fit = math.exp(sol.g[G["log_h"]])
    counts = np.bincount(ps.pair, minlength=ps.n_pairs)
    return [(float(ps.t_mid_s[k]), float(sol.m[k, P["s"]] * height_m / h_fit / ps.dt_s[k]))
            for k in range(ps.n_pairs) if counts[k] > 0 and ps.dt_s[k] > 0]


def _cues_used(sol: Solution, inp: CalibrationInput) -> list[str]:
    out = []
    if sol.n_points:
        masked = (f"; {inp.vehicle_points_masked} points on vehicles dropped"
                  if inp.vehicle_points_masked else "")
        out.append(f"road flow ({sol.n_points} points in {len(inp.pairs)} frame pairs"
                   f"{masked})")
    if inp.motion:
        out.append(f"GPS motion ({inp.gps_label or 'GPS'})")
    if sol.n_vp_frames:
        out.append(f"lane vanishing point ({sol.n_vp_frames} frames)")
    if sol.n_chains:
        out.append(f"plumb lines ({sol.n_chains} straight edges)")
    if sol.cue.get("log_h") == "lane width":
        out.append("lane width")
    return out


def _notes(params: dict[str, ParameterEstimate], sol: Solution, inp: CalibrationInput,
           cfg: CalibrationConfig, lane_note: str | None) -> list[Note]:
    """The estimate line, and a warning for every parameter left at its prior."""
    shown = []
    for key, p in params.items():
        unit = _KEYS[key][2]
        if p.source is ParameterSource.ESTIMATED:
            shown.append(f"{key} {p.value:.4g} +- {p.std:.2g} {unit} ({p.cue})".replace("  ",
                                                                                        " "))
    notes = [Note.estimate("camera self-calibration: " + (", ".join(shown) or "nothing "
                                                           "observable"))]
    if lane_note:
        notes.append(Note.estimate(lane_note))
    priors = {"fx": f"{cfg.hfov_prior_deg:g} deg field of view (dash-cam prior)",
              "height_m": f"{cfg.height_prior_m:g} m (passenger-car windscreen prior)",
              "k1": "no distortion", "roll_deg": "level", "pitch_deg": "level",
              "yaw_deg": "straight ahead"}
    for why in sol.refused.values():
        notes.append(Note.estimate(f"camera {why}"))
    for key, p in params.items():
        if key in sol.refused:
            continue
        if p.source is ParameterSource.PRIOR and key in priors and key != "k2":
            z = _prior_sigmas(key, p.value, inp, cfg)
            kept = (f"prior {p.value:.4g} {_KEYS[key][2]} = {priors[key]}" if abs(z) <= 1.0
                    else f"kept at {p.value:.4g} {_KEYS[key][2]}, {z:+.1f} sigma from the "
                    f"prior ({priors[key]}): the fit moved it with the parameters it trades "
                    "off against, the clip's cues do not fix it: a guess").replace("  ", " ")
            notes.append(Note.warning(
                f"camera {key} not observable in this clip (needs {_NEEDS[key]}): {kept}, "
                f"+- {p.std:.2g}".rstrip()))
    return notes


def _prior_sigmas(key: str, value: float, inp: CalibrationInput, cfg: CalibrationConfig
                  ) -> float:
    """How many prior sigmas ``value`` lies from the named prior's value."""
    if key == "fx":
        f0 = (inp.width_px / 2.0) / math.tan(math.radians(cfg.hfov_prior_deg) / 2.0)
        return math.log(max(value, 1e-9) / f0) / cfg.log_f_prior_std
    if key == "height_m":
        return math.log(max(value, 1e-9) / cfg.height_prior_m) / cfg.log_h_prior_std
    if key == "k1":
        return value / cfg.k1_prior_std
    return value / (cfg.roll_prior_deg if key == "roll_deg" else cfg.mount_prior_deg)
