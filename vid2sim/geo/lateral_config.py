"""Tuning of the ego's lateral fusion (:mod:`vid2sim.geo.lateral`), light to import: the settings tree holds it."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class LateralConfig:
    """Tuning of the lateral fusion (sources in the comments)."""

    #: one-sigma of a GPS fix across the road [m] where the receiver does not say (consumer
    #: receivers in towns: 2-5 m, u-blox M8 datasheet CEP 2.5 m in open sky)
    gps_lateral_std_m: float = 3.0
    #: GPS errors stay correlated for about this long [s] (multipath and atmosphere drift
    #: over seconds; the demo's AR(1) at 1 Hz with rho 0.5 decorrelates in ~2 s)
    gps_correlation_s: float = 2.0
    #: across a gap in the markings (a junction, a car ahead) the ego is taken to hold its
    #: lane for up to this long on either side [s]; farther, GPS places it
    max_hold_s: float = 5.0
    #: between marking-placed and GPS-placed stretches the position is blended over [s]
    blend_s: float = 2.0
    #: a map centerline's kinks at OSM nodes are rounded over this arc length (Gaussian
    #: one-sigma [m]) before the ego is placed on it: a car's path has continuous
    #: curvature. 3 m rounds a node's corner within ~6 m yet moves a 75 m bend inwards by
    #: only sigma^2 / (2 R) = 6 cm
    centerline_smoothing_m: float = 3.0
    #: the markings place the ego only if measured on at least this share of the clip
    min_coverage: float = 0.2
