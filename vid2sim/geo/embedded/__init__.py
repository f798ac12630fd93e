"""GPS read from inside a video file, with the fix times on the video's own clock.

:func:`find_telemetry` lists what a recording carries; :func:`read_embedded` reads the first
GPS track found into a :class:`~vid2sim.core.records.GpsTrace` whose ``video_start_utc_s``
puts every fix on the container's clock (video time 0 = the first frame), so a build needs no
``--gps-offset``. Formats and their sources:

========================  ===============================================================
GoPro GPMF (GPS5, GPS9)   the ``gpmd`` data track (:mod:`.gpmf`, gpmf-parser README)
NMEA 0183 in a track      a subtitle or data track whose samples are NMEA sentences
NMEA 0183 in a box        BlackVue's ``gps `` box of stamped sentences (:mod:`.mp4boxes`)
subtitle telemetry        DJI and dash-cam text cues in a subtitle track, or a sidecar
                          ``.SRT`` file (:mod:`.cuetext`)
========================  ===============================================================

The clock rule (:mod:`.clock`): where the receiver stamps each fix (NMEA, GPS9) its times are
kept and shifted onto the video clock by the median offset between them and the packets'
presentation times; where it does not (GPS5, subtitle cues) a fix's time is its packet's
presentation time (GPS5 samples spread evenly over their payload's duration).
"""

from __future__ import annotations

from vid2sim.geo.embedded.reader import (
    TelemetryTrack,
    find_telemetry,
    read_cue_file,
    read_embedded,
)

__all__ = ["TelemetryTrack", "find_telemetry", "read_cue_file", "read_embedded"]
