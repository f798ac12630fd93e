"""The estimator recovers a known camera from cues rendered through it."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from tests.calib import synthetic
from vid2sim.base.errors import ImpossibleValueError
from vid2sim.calib import CalibrationConfig, CalibrationInput, CameraPrior, calibrate
from vid2sim.core.calibration import ParameterSource

T = synthetic.TRUTH


@pytest.fixture(scope="module")
def cues():
    pairs, motion = synthetic.drive()
    return pairs, motion, synthetic.lines()


def _input(cues, gps=True, prior=None):
    pairs, motion, lines = cues
    return CalibrationInput(T.image_width, T.image_height, pairs, lines,
                            prior or CameraPrior(), motion if gps else None)


def test_recovers_the_camera_with_gps(cues):
    est, _ = calibrate(_input(cues))
    cam = est.camera
    assert abs(cam.fx / T.fx - 1) < 0.03
    assert abs(cam.height_m / T.height_m - 1) < 0.03
    assert abs(cam.dist[0] - T.dist[0]) < 0.03
    assert abs(cam.horizon_y_px() - T.horizon_y_px()) < 1.5
    assert abs(cam.yaw_deg - T.yaw_deg) < 0.3
    assert abs(cam.roll_deg - T.roll_deg) < 0.3
    p = est.parameters
    assert p["fx"].source is ParameterSource.ESTIMATED
    assert p["height_m"].source is ParameterSource.ESTIMATED
    # the spread is honest: the truth within three sigmas
    assert abs(cam.fx - T.fx) < 3 * p["fx"].std + 0.01 * T.fx
    assert abs(cam.height_m - T.height_m) < 3 * p["height_m"].std + 0.01 * T.height_m
    # per-pair speeds at the estimated height follow the drive's
    assert len(est.speeds) >= 30
    assert all(8.0 < v < 16.0 for _, v in est.speeds)


def test_without_gps_the_scale_is_a_named_prior(cues):
    est, _ = calibrate(_input(cues, gps=False))
    p = est.parameters
    assert p["height_m"].source is ParameterSource.PRIOR
    assert p["fx"].source is ParameterSource.PRIOR
    warned = " ".join(str(n) for n in est.notes if n.kind.value == "warning")
    assert "height_m" in warned and "prior" in warned
    # the horizon and lens do not need the scale
    assert abs(est.camera.horizon_y_px() - T.horizon_y_px()) < 3.0


def test_a_partial_prior_is_held_and_the_rest_estimated(cues):
    est, _ = calibrate(_input(cues, prior=CameraPrior({"fx": 900.0})))
    assert est.camera.fx == 900.0
    assert est.parameters["fx"].source is ParameterSource.CAMERA_FILE
    assert abs(est.camera.height_m / T.height_m - 1) < 0.03


@pytest.mark.parametrize("values", [{"fx": -5.0}, {"fx": 1.0}, {"height_m": 40.0},
                                    {"k1": 3.0}, {"pitch_deg": 90.0}, {"cx": 5000.0},
                                    {"fx": math.nan}])
def test_impossible_priors_are_refused(cues, values):
    with pytest.raises(ImpossibleValueError):
        calibrate(_input(cues, prior=CameraPrior(values)))


def test_a_pinhole_lens_is_not_given_a_distortion():
    # The same drive through a lens without distortion: the plumb lines' k1 cannot tell a
    # bow of a few hundredths from the world's curves (their systematic spread), so k1 is
    # refused and held at 0, and the scale is still measured.
    pinhole = replace(T, dist=(0.0, 0.0, 0.0, 0.0, 0.0))
    pairs, motion = synthetic.drive(pinhole)
    est, sol = calibrate(CalibrationInput(T.image_width, T.image_height, pairs,
                                          synthetic.lines(pinhole), CameraPrior(), motion))
    k1 = est.parameters["k1"]
    assert est.camera.dist[0] == 0.0 and k1.source is ParameterSource.PRIOR
    assert k1.std >= CalibrationConfig().k1_systematic_std
    assert "k1" in sol.refused
    assert any("does not exclude 0" in str(n) for n in est.notes)
    assert abs(est.camera.fx / T.fx - 1) < 0.03
    assert abs(est.camera.height_m / T.height_m - 1) < 0.03


def test_a_real_distortion_is_kept_with_its_systematic_spread(cues):
    est, sol = calibrate(_input(cues))
    k1 = est.parameters["k1"]
    assert k1.source is ParameterSource.ESTIMATED and not sol.refused
    # the one-sigma includes the plumb lines' systematic spread, and holds the truth
    assert k1.std >= CalibrationConfig().k1_systematic_std
    assert abs(est.camera.dist[0] - T.dist[0]) < 2 * k1.std
