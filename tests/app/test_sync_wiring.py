"""The build's time sync hands on the offset and a GPS trace re-timed by the clock rate."""

from __future__ import annotations

import pytest

from vid2sim.app import calibrate as cal
from vid2sim.app import selfcal
from vid2sim.app.inputs import Inputs
from vid2sim.app.settings import Settings
from vid2sim.core.calibration import TimeOffset
from vid2sim.core.records import GpsFix, GpsTrace, VideoInfo


def _trace():
    return GpsTrace([GpsFix(1.3e9 + 0.1 * i, 49.0 + 1e-5 * i, 8.4, speed_mps=10.0)
                     for i in range(50)], "csv")


@pytest.mark.parametrize("fitted", [True, False])
def test_sync_applies_the_rate_where_it_applies_the_offset(monkeypatch, fitted):
    off = TimeOffset(1.5, 0.1, True, "test", 1.03 if fitted else 1.0, 0.01, fitted)
    monkeypatch.setattr(cal, "check_cues", lambda cues, video: None)
    monkeypatch.setattr(cal, "sync_clock", lambda *args: off)
    choice = selfcal.CameraChoice(camera=None, cues=cal.Cues(pairs=[], lines=[]))
    trace = _trace()
    inputs, out = selfcal.sync_offset(choice, Inputs(video="clip.mp4", gps="gps.csv"),
                                      VideoInfo(640, 360, 10.0, 100), Settings(), trace)
    assert inputs.gps_offset_s == 1.5
    span = out.fixes[-1].t_utc_s - out.fixes[0].t_utc_s
    if fitted:  # 4.9 GPS s are 4.9 / 1.03 video s; 10 m/s are 10.3 m per video s
        assert span == pytest.approx(4.9 / 1.03)
        assert out.fixes[3].speed_mps == pytest.approx(10.3)
        assert "re-timed" in str(choice.notes[-1])
    else:
        assert out is trace
