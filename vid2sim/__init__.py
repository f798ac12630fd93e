"""vid2sim: turn a geotagged dash-cam video into a replayable driving scenario."""

__version__ = "0.1.0"
