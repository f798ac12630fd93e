"""How the street is laid out from the video (:mod:`vid2sim.export.scenelayout`), light to import: the settings tree holds it."""

from __future__ import annotations

from dataclasses import dataclass, field

from vid2sim.export.assemble import AssembleConfig
from vid2sim.export.crosssection import CrossSectionConfig


@dataclass(frozen=True)
class LayoutConfig:
    """Tuning of :func:`lay_out_scene` (sources in the comments)."""

    cross_section: CrossSectionConfig = field(default_factory=CrossSectionConfig)
    #: which actors count as static where assembly did not hold them (the demo's phone GPS)
    assemble: AssembleConfig = field(default_factory=AssembleConfig)
    #: Gaussian one-sigma of the lane-middle path's smoothing [m]: the path is the GPS/INS
    #: ego path shifted by the filtered lane offset (cm-level), 2 m removes the heading
    #: jitter between samples without rounding a 50 m bend (offset sigma^2 / 2R = 4 cm)
    reference_smoothing_m: float = 2.0
    #: a parked car is moved into its strip when its centre lies outside it by at most
    #: this [m]: the monocular lateral scatter of parked cars at 10-40 m
    #: (0.3-0.8 m, tests/detect/test_ranging_parked.py)
    snap_tolerance_m: float = 1.0
    #: the reference line reaches this far beyond the farthest actor [m]
    end_margin_m: float = 10.0
    #: at most this many metres of straight road are added at either end [m]
    max_extension_m: float = 300.0
    #: a vehicle off the road (outside its driving, parking and shoulder lanes; one standing
    #: in a strip keeps its measured track, whose drift reprojects onto its boxes: the demo's
    #: keyframe F1 fell from 0.956 to 0.911 when those were held too) that seems to move
    #: along the road slower than
    #: the ego (this share of its speed), or against it at up to ``off_road_max_back_share``
    #: of it, is a standing one whose monocular range is off by the factor k = 1 - v/u
    #: (u the ego's speed): a car parked side-on in a lot is ranged by its rear-view width
    #: prior 1.8 m against its 4.5 m length seen (k = 0.4, apparent v = 0.6 u); a box cut
    #: by a hedge reads too far (k > 1, apparent oncoming). KITTI raw 0001: the car park
    #: on the left, tracks at 0.4-0.85 u forward and one at 1.3 u backward.
    off_road_max_forward_share: float = 1.0
    off_road_max_back_share: float = 2.0
