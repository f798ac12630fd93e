"""The one definition of the lead vehicle, shared by tracking, the report and the environment.

The lead is the nearest vehicle AHEAD of the ego (its rear beyond the ego's reference point,
within a maximum range) whose centre lies in the ego's corridor: within half a lane width of
the ego's lane centre, measured across the lane. Tracking adds hysteresis on top (a car
drifting along a lane line keeps its lane; a rival must be clearly nearer to take over, see
:mod:`vid2sim.detect.lead`), but the geometry is this one.
"""

from __future__ import annotations

import math

import numpy as np


def in_ego_corridor(lateral_m: np.ndarray | float, lane_width_m: float) -> np.ndarray:
    """True where a centre ``lateral_m`` across the ego lane's centre line [m] lies in the ego
    lane (boundary included)."""
    return np.abs(np.asarray(lateral_m, dtype=float)) <= lane_width_m / 2.0


def nearest_ahead(ahead_m: np.ndarray, candidate: np.ndarray,
                  max_range_m: float = math.inf) -> int:
    """Index of the nearest candidate with ``0 < ahead_m <= max_range_m``, or -1.

    Parameters
    ----------
    ahead_m : ndarray
        Distance from the ego's reference point to each vehicle's rear along the lane [m]
        (NaN for unknown).
    candidate : ndarray of bool
        Vehicles that may be the lead (in the ego corridor).
    max_range_m : float
        Farther vehicles are not the lead [m].
    """
    ahead = np.asarray(ahead_m, dtype=float)
    ok = np.asarray(candidate, dtype=bool) & np.isfinite(ahead) & (ahead > 0) & (
        ahead <= max_range_m)
    if not ok.any():
        return -1
    idx = np.flatnonzero(ok)
    return int(idx[np.argmin(ahead[idx])])


def lead_of(ahead_m: np.ndarray, lateral_m: np.ndarray, lane_width_m: float,
            max_range_m: float = math.inf) -> int:
    """Index of the lead among vehicles at ``ahead_m`` (to their rear) and ``lateral_m`` (of
    their centre) relative to the ego lane [m], or -1 when there is none."""
    return nearest_ahead(ahead_m, in_ego_corridor(lateral_m, lane_width_m), max_range_m)
