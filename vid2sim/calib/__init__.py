"""Camera self-calibration: focal length, lens, mount and height from the video itself.

A stage of its own (like ``geo``, ``detect`` and ``export``): it receives records (the
detect wings' flow pairs, lane segments and straight edges; the GPS motion on the video
clock, which the application layer derives from the geo stage's trajectory) and returns a
:class:`~vid2sim.core.calibration.CameraEstimate`. It imports no other stage.

- :func:`calibrate`: one robust least-squares fit of every cue (:mod:`.solve`,
  :mod:`.estimate`), the lane width folded in when measured (:func:`with_lanes`);
- :func:`estimate_time_offset`: the GPS clock against the video's (:mod:`.sync`).
"""

from __future__ import annotations

from threadpoolctl import threadpool_limits  # installed with scikit-learn

from vid2sim.calib.calibconfig import CalibrationConfig
from vid2sim.calib.cues import CalibrationInput, CameraPrior, LaneWidthPrior
from vid2sim.calib.estimate import Solution, solve_camera
from vid2sim.calib.result import camera_estimate, with_lane_widths
from vid2sim.core.calibration import CameraEstimate, LaneWidthSample

__all__ = ["CalibrationConfig", "CalibrationInput", "CameraPrior", "LaneWidthPrior",
           "Solution", "calibrate", "with_lanes"]


def calibrate(inp: CalibrationInput, config: CalibrationConfig | None = None
              ) -> tuple[CameraEstimate, Solution]:
    """The camera of a clip's cues, and the fit behind it (for :func:`with_lanes`)."""
    cfg = config or CalibrationConfig()
    inp.prior.check(inp.width_px, inp.height_px)
    # One BLAS thread: the fit's few-hundred-column eigen- and singular-value decompositions
    # take 6 ms each on one thread and 300 ms when OpenBLAS spreads them over busy cores.
    with threadpool_limits(limits=1, user_api="blas"):
        sol = solve_camera(inp, cfg)
    return camera_estimate(sol, inp, cfg), sol


def with_lanes(sol: Solution, inp: CalibrationInput, samples: list[LaneWidthSample],
               config: CalibrationConfig | None = None) -> CameraEstimate:
    """The estimate with the ego lane's measured width folded in (the height, and through
    the road's motion the focal length)."""
    cfg = config or CalibrationConfig()
    sol, note = with_lane_widths(sol, samples, inp.lane_prior)
    return camera_estimate(sol, inp, cfg, note)
