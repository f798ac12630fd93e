"""How the report's sampled frames are chosen and drawn (:mod:`vid2sim.evaluate.frames`), light to import: the settings tree holds it."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class FrameSampleConfig:
    """How many frames, and how they are drawn."""

    #: frames spread evenly over the clip (plus one per event, up to ``max_event_frames``):
    #: enough to see the scene change, few enough to look at each
    n_even: int = 6
    max_event_frames: int = 8
    #: the lane boundaries are drawn over this range ahead [m]: from the bonnet to where the
    #: lane model is trusted (vid2sim.core.lead.LANE_MODEL_REACH_M) and a little beyond
    lane_near_m: float = 4.0
    lane_far_m: float = 35.0
    #: the highway-env render: a square [px] at a scale [px/m] showing 50 m ahead of the
    #: ego (the lane model's reach and the events' 30 m, with the far lead), cut 12 m
    #: behind it
    render_size_px: int = 600
    render_scale_px_per_m: float = 6.0
    render_behind_m: float = 12.0
