"""The GPS trace of a run, read and smoothed on the run's time base: shared by ``trace``,
``road``, ``build`` and ``batch``, and light (no map, no detection stack), so that every
command that loads it stays as fast to start as its own stack allows."""

from __future__ import annotations

from pathlib import Path

from vid2sim.app.inputs import Inputs
from vid2sim.app.settings import Settings
from vid2sim.base.errors import MissingInputError
from vid2sim.core.records import EgoTrack, GpsTrace, TraceStats
from vid2sim.geo import trace as geo_trace
from vid2sim.geo.readers import read_gps


def load_trace(inputs: Inputs) -> GpsTrace:
    """The GPS trace of ``inputs.gps`` (format detected from the content)."""
    if inputs.gps is None:
        raise MissingInputError(None, "no GPS trace given")
    return read_gps(Path(inputs.gps))


def smooth_trace(trace: GpsTrace, inputs: Inputs, settings: Settings
                 ) -> tuple[EgoTrack, TraceStats]:
    """The ego trajectory of a trace on the run's GPS time base (``inputs.gps_offset_s``)."""
    return geo_trace.smooth_ego(trace, rate_hz=settings.rate_hz,
                                gps_offset_s=inputs.gps_offset_s, params=settings.trace)
