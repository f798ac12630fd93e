"""GPMF (GoPro telemetry): real payloads and recording from GoPro's gpmf-parser samples, and
property tests of the KLV reader on payloads written from the gpmf-parser README."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.conftest import DATA
from tests.geo import recordings as rec
from vid2sim.base.errors import FormatError
from vid2sim.cli import main
from vid2sim.core.records import GpsFix
from vid2sim.geo.embedded import find_telemetry, read_embedded
from vid2sim.geo.embedded.gpmf import GpmfError, gpsu_time, iter_klv, payload_gps
from vid2sim.geo.trace import smooth_ego

#: GoPro's own sample recordings (github.com/gopro/gpmf-parser, folder ``samples/``:
#: hero5.raw, hero6.raw, max-heromode.mp4; Apache-2.0 or MIT) are third-party data: they are
#: not part of this repository and are looked for beside the other real data.
SAMPLES = DATA / "gopro"


@pytest.fixture(autouse=True)
def _needs_samples(request):
    if "real" in request.node.name and not SAMPLES.is_dir():
        pytest.skip(f"GoPro's gpmf-parser samples not found at {SAMPLES} (copy its samples/ "
                    "hero5.raw, hero6.raw and max-heromode.mp4 there)")


def test_a_real_hero5_payload_holds_18_gps5_samples_with_a_3d_lock():
    (gps,) = payload_gps((SAMPLES / "hero5.raw").read_bytes())
    assert gps.kind == "GPS5" and gps.fix == 3 and len(gps.rows) == 18
    lat, lon, _, speed, _, dop = gps.rows[0]
    # GoPro's office in Carlsbad, California (the samples' recording place)
    assert lat == pytest.approx(33.1265, abs=1e-3) and lon == pytest.approx(-117.3274, abs=1e-3)
    assert 0 <= speed < 1 and dop == pytest.approx(6.06)
    assert gps.utc_s == pytest.approx(gpsu_time("170417174103.000"), abs=86400)


def test_a_real_hero6_payload_without_a_lock_says_fix_0():
    (gps,) = payload_gps((SAMPLES / "hero6.raw").read_bytes())
    assert gps.fix == 0 and len(gps.rows) == 17


def test_the_real_gopro_max_recording_reads_onto_its_video_clock():
    video = SAMPLES / "max-heromode.mp4"
    (track,) = find_telemetry(video)
    assert track.kind == "gpmf" and track.label == "GoPro MET"
    trace = read_embedded(video)
    assert len(trace.fixes) == 191  # 11 payloads of 10-19 GPS5 samples
    # 18 Hz GPS5 (gpmf-parser README: HERO5-HERO10 GPS5 at 18 Hz)
    t = [f.t_utc_s - trace.video_start_utc_s for f in trace.fixes]
    rate = (len(t) - 1) / (t[-1] - t[0])
    assert 17.0 < rate < 19.0 and t[0] == pytest.approx(0.0, abs=1e-6) and t[-1] < 10.6
    ego, _ = smooth_ego(trace)
    assert 0.5 < float(ego.speed_mps.mean()) < 2.0  # a walk


def test_probe_shows_the_real_recordings_telemetry(capsys):
    assert main(["probe", str(SAMPLES / "max-heromode.mp4")]) == 0
    out = capsys.readouterr().out
    assert "gpmf (GoPro MET): 191 fixes" in out and "848x480" in out and "h264" in out


# --------------------------------------------------------------------------- properties

_lat = st.floats(-89.9, 89.9, allow_nan=False)
_lon = st.floats(-179.9, 179.9, allow_nan=False)
_fix = st.builds(lambda lat, lon, alt, v: GpsFix(1.7e9, lat, lon, alt, v),
                 _lat, _lon, st.floats(-400, 8000), st.floats(0, 60))


@given(st.lists(_fix, min_size=1, max_size=40))
def test_gps5_written_by_the_readme_reads_back_within_its_scale(fixes):
    (gps,) = payload_gps(rec.gps5_payload(fixes))
    assert len(gps.rows) == len(fixes)
    for (lat, lon, alt, speed, _, _), f in zip(gps.rows, fixes, strict=True):
        assert abs(lat - f.lat_deg) <= 1e-7 and abs(lon - f.lon_deg) <= 1e-7
        assert abs(alt - f.alt_m) <= 1e-3 and abs(speed - f.speed_mps) <= 1e-3


@given(st.lists(_fix, min_size=1, max_size=20),
       st.floats(0.0, 86_000.0).map(lambda s: 1.7e9 + round(s, 3)))
def test_gps9_carries_each_samples_own_time(fixes, t0):
    stamped = [GpsFix(t0 + 0.1 * k, f.lat_deg, f.lon_deg, f.alt_m, f.speed_mps)
               for k, f in enumerate(fixes)]
    (gps,) = payload_gps(rec.gps9_payload(stamped))
    assert [round(r[4], 3) for r in gps.rows] == [round(f.t_utc_s, 3) for f in stamped]


@given(st.lists(_fix, min_size=1, max_size=10), st.data())
def test_a_cut_payload_is_a_gpmf_error_never_a_crash(fixes, data):
    payload = rec.gps5_payload(fixes)
    cut = data.draw(st.integers(1, len(payload) - 1))
    try:
        found = payload_gps(payload[:cut])
    except GpmfError:
        return
    # a cut at a KLV boundary leaves a shorter valid payload: never more samples
    assert sum(len(g.rows) for g in found) <= len(fixes)


@given(st.binary(max_size=300))
def test_any_bytes_parse_or_raise_gpmf_error(blob):
    try:
        list(iter_klv(blob))
        payload_gps(blob)
    except GpmfError:
        pass


def test_a_real_no_lock_payload_in_a_real_recording_is_a_format_error(tmp_path):
    hero6 = (SAMPLES / "hero6.raw").read_bytes()  # the real payload, no lock
    video = rec.remux_with_telemetry(SAMPLES / "max-heromode.mp4", tmp_path / "nolock.mp4",
                                     "gpmf", [(0.0, 1.0, hero6), (1.0, 1.0, hero6)])
    with pytest.raises(FormatError):  # a GPMF track without one GPS fix
        read_embedded(video)
