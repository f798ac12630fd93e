"""PNG figures of a build's stages for the report (road match, lead range, top-down tracks)."""

from __future__ import annotations

from pathlib import Path

from vid2sim.core.records import EgoTrack, GpsTrace, RangedBox, RoadResult
from vid2sim.detect import plots
from vid2sim.geo.roads import plot_road


def stage_figures(fig_dir: Path, road_result: RoadResult | None, trace: GpsTrace | None,
                  ego: EgoTrack, boxes: list[RangedBox]) -> list[tuple[str, Path]]:
    """Draw the stage figures into ``fig_dir``; (caption, path) of each, in report order."""
    fig_dir.mkdir(parents=True, exist_ok=True)
    figures: list[tuple[str, Path]] = []
    if road_result is not None and trace is not None:
        path = fig_dir / "road.png"
        plot_road(road_result, trace, ego, path)
        figures.append(("OSM roads, GPS fixes, matched route and smoothed ego path", path))
    if boxes:
        path = fig_dir / "lead_range.png"
        plots.plot_lead(boxes, path)
        figures.append(("Lead range and range rate (band: one sigma)", path))
        path = fig_dir / "tracks_topdown.png"
        plots.plot_topdown(boxes, path)
        figures.append(("Top-down view of all tracks (camera frame)", path))
    return figures
