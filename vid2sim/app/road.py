"""The road stage on the run's GPS time base, shared by ``vid2sim road`` and ``build``.

A module of its own so that ``build`` loads the road stack (map reading, map matching) without
the export and evaluation stacks that :mod:`vid2sim.app.commands` brings.
"""

from __future__ import annotations

from vid2sim.app.inputs import Inputs
from vid2sim.app.settings import Settings
from vid2sim.geo import roads as geo_roads
from vid2sim.records import EgoTrack, GpsTrace, RoadResult


def match_road(trace: GpsTrace, ego: EgoTrack, inputs: Inputs, settings: Settings) -> RoadResult:
    """The road network for the trace (the map given, the cache, or a download) and the
    trace matched to it, on the run's GPS time base."""
    return geo_roads.build_road(
        trace, ego, inputs.map, allow_download=settings.allow_download,
        cache_dir=settings.osm_cache_dir, gps_offset_s=inputs.gps_offset_s)
