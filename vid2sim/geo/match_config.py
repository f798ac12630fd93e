"""Tuning of the map matcher (:mod:`vid2sim.geo.mapmatch`), light to import: the settings tree holds it."""

from __future__ import annotations

from dataclasses import dataclass

from vid2sim.base.defaults import EGO_LENGTH_M


@dataclass(frozen=True, slots=True)
class MatchConfig:
    """Tuning of the matcher (defaults suit consumer GPS at 1-10 Hz in cities).

    :param sigma_m: GPS position noise, one sigma [m], for fixes without an accuracy; None
        estimates it from the trace (:func:`estimate_sigma`, then the matched route's offsets)
    :param min_sigma_m, max_sigma_m: bounds of the estimate [m]: OSM draws a way's middle to
        a metre or two and a car drives up to half a carriageway beside it; beyond 50 m a
        trace says little about streets
    :param refine_sigma: re-estimate the noise from the matched route's offsets and match
        again when it is clearly larger than the first estimate
    :param search_radius_m: candidate edges are searched within this distance of a fix, or
        ``search_sigmas`` sigma if farther [m]
    :param search_sigmas: search radius in units of sigma
    :param max_geometries: nearest way pieces kept per fix (each gives 1-2 directed edges)
    :param beta_m: scale of the route-vs-straight distance difference [m]
    :param thin_sigmas: the HMM reasons about fixes at least this many sigma apart
        (:func:`hmm_steps`); 0 uses every fix
    :param obs_window_s: fixes less than this apart are one observation for the HMM (their
        median, :func:`observations`): under a second, so a 1 Hz trace with some clock
        jitter is used fix by fix and a 10 Hz one as about 1 Hz [s]
    :param heading_sigma_rad: heading error scale of the emission [rad]
    :param heading_cap_logp: the heading term never costs more than this (a wrong heading
        estimate must not veto the right road)
    :param max_skip: consecutive fixes the chain may skip as outliers
    :param skip_logp: log-probability cost of one skipped fix
    :param break_logp: cost of restarting the chain (no connection found)
    :param uturn_logp: cost of turning onto the twin edge
    :param max_speed_mps: transitions faster than this are impossible [m/s]
    :param prune_beta: where the trace tells the distance driven between two fixes, a route
        longer than it by more than this many ``beta_m`` is impossible: its transition
        probability, e^-30 = 1e-13, is below that of breaking the chain (``break_logp``
        plus the emission), and the route searches stop there instead of at
        ``max_speed_mps`` times the time (1.3 km after a 20 s stop)
    :param off_map_sigmas: observations at the start or end of a trace farther than this
        many sigma from every drivable road (4 sigma: 1 in 15,000 fixes of a car on the road
        by noise alone) are off the map when at least ``off_map_fixes`` of them follow each
        other (a car park, private ground): they are left out, not matched to the nearest
        street (:func:`on_map`); single far fixes inside the trace stay the HMM's outliers
    :param off_map_fixes: shortest such run at either end, in observations
    :param accel_sigma_mps2: process noise of the along-route smoother [m/s^2]
    :param stationary_mps: below this speed the car is taken as standing still, and a
        projection that moves backwards on the same edge costs no more than one forwards
    :param turn_m_per_rad: turning at a junction counts as this many extra metres of route
        per radian (prefers the straighter of two nearly equal routes) [m/rad]
    :param min_cover_m: a first/last edge the fixes cover less than this is dropped from the
        route (GPS noise at the start would otherwise add the way behind the start) [m]
    :param service_logp: emission prior of a candidate on a ``highway=service`` way (an
        access road or alley beside a street): a car is likelier on the street when the two
        are equally near, as routing engines weigh them (Valhalla's auto costing adds a
        ``service_penalty``); -1 nat measured on the Helsinki benchmark (0.2 Hz, 3 m noise:
        mean RMF 0.23 -> 0.07 %, other cells within 0.2 points), deeper priors cost more at
        5 m noise than they gain
    :param route_margin_m: the road built on the route (road.json, the scenario's road,
        OpenDRIVE) runs from this far before the projection of the first matched fix to this
        far beyond that of the last: one car length (``EGO_LENGTH_M``), so the ego's rear at
        its first fix and its front at its last lie on the road, and nothing of the way
        before the start or after the end, which the car was never seen on [m]
    """

    sigma_m: float | None = None
    min_sigma_m: float = 2.0
    max_sigma_m: float = 50.0
    refine_sigma: bool = True
    search_radius_m: float = 40.0
    search_sigmas: float = 4.0
    max_geometries: int = 6
    beta_m: float = 5.0
    thin_sigmas: float = 2.0
    obs_window_s: float = 0.9
    heading_sigma_rad: float = 0.5
    heading_cap_logp: float = -4.0
    max_skip: int = 3
    skip_logp: float = -8.0
    break_logp: float = -60.0
    uturn_logp: float = -20.0
    max_speed_mps: float = 60.0
    prune_beta: float = 30.0
    off_map_sigmas: float = 4.0
    off_map_fixes: int = 3
    accel_sigma_mps2: float = 1.5
    stationary_mps: float = 1.5
    min_cover_m: float = 3.5
    turn_m_per_rad: float = 10.0
    route_margin_m: float = EGO_LENGTH_M
    service_logp: float = -1.0
