"""The results index (parquet and CSV), the lead figures of a row, the fleet page."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from hypothesis import given
from hypothesis import strategies as st

from vid2sim.app.batch.fleet import render_fleet, stage_times, write_fleet_report
from vid2sim.app.batch.index import (
    FIXED_COLUMNS,
    RowOutcome,
    index_record,
    read_index,
    stage_column,
    write_index,
)
from vid2sim.app.batch.manifest import BatchRow
from vid2sim.app.batch.worker import TTC_MIN_CLOSING_MPS, _lead_motion
from vid2sim.core.records import RangedBox
from vid2sim.core.tables import write_tracks_csv

_text = st.text(st.characters(codec="utf-8", exclude_characters="\r\n\x00"), max_size=40)
_opt_float = st.none() | st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False)
_opt_int = st.none() | st.integers(0, 10**6)


@st.composite
def outcomes(draw) -> RowOutcome:
    o = RowOutcome(name=draw(st.text("abcdefghij_0123456789", min_size=1, max_size=10)),
                   status=draw(st.sampled_from(["ok", "skipped", "failed", "pending"])),
                   line=draw(st.integers(2, 10**6)), error=draw(_text), host=draw(_text),
                   attempts=draw(st.integers(0, 9)))
    for name in ("seconds", "peak_rss_mb", "duration_s", "distance_m", "lead_share", "f1",
                 "mean_iou", "lead_range_median_m", "lead_ttc_min_s"):
        setattr(o, name, draw(_opt_float))
    o.actors, o.n_keyframes = draw(_opt_int), draw(_opt_int)
    o.sha256 = draw(st.dictionaries(st.sampled_from(["video", "gps"]),
                                    st.text("0123456789abcdef", min_size=64, max_size=64)))
    o.sha256.setdefault("video", "0" * 64)
    o.stage_s = draw(st.dictionaries(st.sampled_from(["read GPS", "detect, track and range"])
                                     .map(stage_column), st.floats(0, 1e4)))
    return o


def _row(o: RowOutcome, tmp: Path) -> BatchRow:
    return BatchRow(line=o.line, name=o.name, video=tmp / "v.mp4",
                    gps=tmp / "g.gpx" if "gps" in o.sha256 else None)


def _same(a, b) -> bool:
    if isinstance(a, float) and b is not None:
        return math.isclose(a, b, rel_tol=1e-5, abs_tol=1e-9)
    return a == b


@given(st.lists(outcomes(), min_size=1, max_size=5, unique_by=lambda o: o.name))
def test_index_round_trips_through_parquet_and_csv(tmp_path_factory, items):
    tmp = tmp_path_factory.mktemp("idx")
    write_index(tmp, [index_record(_row(o, tmp), o) for o in items])
    from_parquet = read_index(tmp)
    (tmp / "index.parquet").unlink()
    from_csv = read_index(tmp)  # index.csv alone: what a user without pyarrow has
    for back in (from_parquet, from_csv):
        assert list(back) == [o.name for o in items]
        for o in items:
            b = back[o.name]
            for name in ("status", "line", "attempts", "actors", "n_keyframes", "seconds",
                         "f1", "lead_ttc_min_s", "distance_m"):
                assert _same(getattr(o, name), getattr(b, name)), (name, o, b)
            assert b.error == o.error and b.host == o.host
            assert b.sha256 == o.sha256
            assert set(b.stage_s) == set(o.stage_s)


def test_index_columns_are_the_fixed_ones_then_the_stages(tmp_path):
    o = RowOutcome(name="a", status="ok", stage_s={stage_column("replay evaluation"): 2.0})
    write_index(tmp_path, [index_record(BatchRow(line=2, name="a", video=tmp_path / "v"), o)])
    names = pq.read_table(tmp_path / "index.parquet").schema.names
    assert names == [c for c, _ in FIXED_COLUMNS] + ["stage_replay_evaluation_s"]
    with open(tmp_path / "index.csv", encoding="utf-8", newline="") as fh:
        assert next(csv.reader(fh)) == names


@pytest.mark.parametrize("stage, column", [
    ("detect, track and range", "stage_detect_track_and_range_s"),
    ("export OpenSCENARIO/OpenDRIVE", "stage_export_openscenario_opendrive_s"),
    ("read GPS", "stage_read_gps_s"),
])
def test_stage_columns(stage, column):
    assert stage_column(stage) == column


def _box(frame: int, range_m: float, rate_mps: float, lead: bool = True) -> RangedBox:
    return RangedBox(frame=frame, t_s=frame / 10.0, track_id=1 if lead else 2, category="car",
                     score=0.9, x1=0.0, y1=0.0, x2=10.0, y2=10.0, range_m=range_m,
                     lateral_m=0.0, range_rate_mps=rate_mps, range_std_m=0.5, is_lead=lead)


def test_lead_ttc_is_range_over_closing_speed_above_the_noise_floor(tmp_path):
    # A lead 30 m ahead closing at 3 m/s, then 20 m closing at 4 m/s: TTC 10 s and 5 s; a
    # slower close (range 10 m, 0.5 m/s: below the floor) and a non-lead give no TTC.
    boxes = [_box(0, 30.0, -3.0), _box(1, 20.0, -4.0), _box(2, 10.0, -0.5),
             _box(3, 5.0, -9.0, lead=False), _box(4, 25.0, float("nan"))]
    assert TTC_MIN_CLOSING_MPS > 0.5
    write_tracks_csv(boxes, tmp_path / "tracks.csv")
    o = RowOutcome(name="x", status="ok")
    _lead_motion(o, tmp_path / "tracks.csv")
    assert o.lead_ttc_min_s == pytest.approx(5.0)
    assert o.lead_closing_speed_max_mps == pytest.approx(4.0)
    assert o.lead_range_rate_median_mps == pytest.approx(-3.0)
    assert (o.lead_range_min_m, o.lead_range_median_m, o.lead_range_max_m) == (10.0, 20.0, 30.0)


def test_a_lead_that_opens_the_gap_has_no_ttc(tmp_path):
    write_tracks_csv([_box(0, 20.0, 1.0), _box(1, 21.0, 1.0)], tmp_path / "tracks.csv")
    o = RowOutcome(name="x", status="ok")
    _lead_motion(o, tmp_path / "tracks.csv")
    assert o.lead_ttc_min_s is None and o.lead_closing_speed_max_mps == 0.0


# --------------------------------------------------------------------------- fleet page


def _records() -> list[dict]:
    recs = []
    for k in range(6):
        recs.append({"id": f"v{k}", "status": "ok" if k < 4 else "failed",
                     "error": "" if k < 4 else f"v{k}.mp4: OpenCV cannot open this video",
                     "duration_s": 30.0, "lead_range_median_m": 10.0 + k,
                     "lead_ttc_min_s": 4.0 + k if k < 2 else None, "f1": 0.8,
                     "report": f"v{k}/report.html" if k < 4 else None, "seconds": 5.0,
                     "stage_replay_evaluation_s": 2.0, "stage_read_gps_s": 0.1,
                     "attempts": 1, "host": "node-1"})
    return recs


def test_fleet_page_counts_times_links_and_distributions():
    page = render_fleet(_records(), "/data/batch")
    assert "<b>4</b>ok" in page and "<b>2</b>failed" in page and "<b>6</b>videos" in page
    assert "2.0 min" in page, "4 built videos of 30 s"
    assert page.count("href='v") == 4 and "href='v4/report.html'" not in page
    assert "OpenCV cannot open this video" in page
    assert page.count("data:image/png;base64,") == 2
    # Failed rows come first in the table.
    assert page.index(">v4<") < page.index(">v0</a>")


def test_stage_times_total_and_median_slowest_first():
    times = stage_times(_records())
    assert times[0] == ("replay evaluation", 6, 12.0, 2.0)
    assert times[1][0] == "read gps" and times[1][2] == pytest.approx(0.6)


def test_fleet_page_of_a_folder_is_written_beside_its_index(tmp_path):
    rows = [BatchRow(line=2, name="a", video=tmp_path / "v")]
    write_index(tmp_path, [index_record(rows[0], RowOutcome(name="a", status="ok"))])
    assert write_fleet_report(tmp_path) == tmp_path / "fleet.html"
    assert "vid2sim fleet summary" in (tmp_path / "fleet.html").read_text(encoding="utf-8")
