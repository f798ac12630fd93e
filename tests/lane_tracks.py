"""Lane tracks built in code for the lane tests (no video)."""

from __future__ import annotations

import numpy as np

from vid2sim.core.records import LaneTrack


def make_track(t_s, lateral_m, width_m=3.0, heading_rad=0.0, curvature_inv_m=0.0,
               lane=None) -> LaneTrack:
    """A lane track with the given continuous lateral position (lanes from it if not given)."""
    t = np.asarray(t_s, float)
    n = len(t)
    lat = np.broadcast_to(np.asarray(lateral_m, float), (n,)).copy()
    w = np.broadcast_to(np.asarray(width_m, float), (n,)).copy()
    ln = np.round(lat / w).astype(int) if lane is None else np.asarray(lane, int)
    return LaneTrack(
        frame=np.arange(n), t_s=t, found=np.ones(n, bool), ego_offset_raw_m=lat - ln * w,
        ego_offset_m=lat - ln * w, offset_std_m=np.full(n, 0.05), lateral_m=lat, lane=ln,
        lane_width_m=w, heading_rad=np.broadcast_to(np.asarray(heading_rad, float), (n,)).copy(),
        curvature_inv_m=np.broadcast_to(np.asarray(curvature_inv_m, float), (n,)).copy())
