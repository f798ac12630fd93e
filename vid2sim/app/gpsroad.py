"""The GPS commands ``trace`` and ``road``, and the road stage ``build`` shares with them.

Only the GPS readers, the smoother, the map and the matcher are loaded here (no detection,
export or evaluation stack), so ``vid2sim road`` and ``vid2sim trace`` start in a fraction of a
second. Each takes the run's :class:`~vid2sim.app.inputs.Inputs` and
:class:`~vid2sim.app.settings.Settings`, checks that its output can be written before any
work and writes it atomically; each returns the summary text the CLI prints.
"""

from __future__ import annotations

from pathlib import Path

from vid2sim.app.gpsinputs import load_trace, smooth_trace
from vid2sim.app.inputs import Inputs
from vid2sim.app.settings import Settings
from vid2sim.base.fileio import check_output_file, write_text_atomic
from vid2sim.core.records import EgoTrack, GpsTrace, RoadResult
from vid2sim.core.scenario import dumps_canonical
from vid2sim.core.tables import write_ego_csv
from vid2sim.geo import roads as geo_roads
from vid2sim.geo import trace as geo_trace


def run_trace(inputs: Inputs, out_path: Path, settings: Settings | None = None) -> str:
    """``vid2sim trace``: read the GPS trace, smooth it, write ``ego.csv``; the summary."""
    settings = settings or Settings()
    inputs.check()
    check_output_file(out_path)
    trace = load_trace(inputs)
    ego, stats = smooth_trace(trace, inputs, settings)
    write_ego_csv(ego, out_path)
    return geo_trace.format_summary(stats, out_path)


def match_road(trace: GpsTrace, ego: EgoTrack, inputs: Inputs, settings: Settings
               ) -> RoadResult:
    """The road stage on the run's GPS time base (shared by ``road`` and ``build``)."""
    return geo_roads.build_road(
        trace, ego, inputs.map, allow_download=settings.allow_download,
        cache_dir=settings.osm_cache_dir, gps_offset_s=inputs.gps_offset_s,
        config=settings.matching)


def run_road(inputs: Inputs, out_path: Path, settings: Settings | None = None,
             plot_path: Path | None = None) -> str:
    """``vid2sim road``: match the trace to OpenStreetMap, write ``road.json`` (and a PNG)."""
    settings = settings or Settings()
    inputs.check()
    check_output_file(out_path)
    if plot_path is not None:
        check_output_file(plot_path)
    trace = load_trace(inputs)
    ego, _ = smooth_trace(trace, inputs, settings)
    result = match_road(trace, ego, inputs, settings)
    write_text_atomic(out_path, dumps_canonical(geo_roads.road_json(result)))
    if plot_path is not None:
        geo_roads.plot_road(result, trace, ego, plot_path)
    return geo_roads.format_summary(result, Path(out_path))
