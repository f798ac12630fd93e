"""Monocular range, lateral offset and range rate of tracked vehicles (boxes -> metres).

Modules by concern: :mod:`.config` (vehicle priors, :class:`RangingConfig`), :mod:`.boxfit`
(the single-frame fit of each box), :mod:`.horizon` (where the horizon is, per video and per
frame), :mod:`.parallax` and :mod:`.surface` (standing vehicles ranged from the ego's own
motion, and the ground under each car), :mod:`.smoother` (Kalman filter and RTS smoother per track) and :mod:`.core`
(:func:`range_tracks`, which wires them). The public names are re-exported here.
"""

from __future__ import annotations

from vid2sim.detect.ranging.boxfit import (
    BoxArrays,
    BoxFit,
    colored_noise_factor,
    fit_boxes,
    predict_edges,
)
from vid2sim.detect.ranging.config import (
    CALIBRATED_PITCH_STD_DEG,
    DEFAULT_PRIORS,
    GUESSED_PITCH_STD_DEG,
    RangingConfig,
    VehiclePrior,
    cuboid_config,
)
from vid2sim.detect.ranging.core import range_tracks
from vid2sim.detect.ranging.horizon import (
    choose_horizon,
    frame_horizon_offsets,
    horizon_from_vehicles,
    lane_horizon_offsets,
    pitch_for_horizon,
)
from vid2sim.detect.ranging.parallax import EgoPath, fit_standing_track, standing_range_rate
from vid2sim.detect.ranging.smoother import SmoothedTrack, smooth_track, smooth_track_adaptive

__all__ = [
    "CALIBRATED_PITCH_STD_DEG",
    "DEFAULT_PRIORS",
    "GUESSED_PITCH_STD_DEG",
    "BoxArrays",
    "BoxFit",
    "EgoPath",
    "RangingConfig",
    "SmoothedTrack",
    "VehiclePrior",
    "choose_horizon",
    "colored_noise_factor",
    "cuboid_config",
    "fit_boxes",
    "fit_standing_track",
    "frame_horizon_offsets",
    "horizon_from_vehicles",
    "lane_horizon_offsets",
    "pitch_for_horizon",
    "predict_edges",
    "range_tracks",
    "smooth_track",
    "smooth_track_adaptive",
    "standing_range_rate",
]
