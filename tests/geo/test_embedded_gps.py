"""GPS inside the video: each format read onto the video clock, the same trajectory as the
same fixes given as a separate file, and the builds that use it (with and without --gps)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from tests.geo import recordings as rec
from vid2sim.base.errors import FormatError
from vid2sim.cli import main
from vid2sim.geo.embedded import find_telemetry, read_embedded
from vid2sim.geo.readers import read_gps
from vid2sim.geo.trace import smooth_ego

#: Embedded format -> the fields it carries besides time and position (for the CSV copy).
FIELDS = {"gpmf-gps5": ("alt", "speed"), "gpmf-gps9": ("alt", "speed"),
          "nmea-track": ("alt", "speed", "heading"), "nmea-box": ("alt", "speed", "heading"),
          "dji-cues": ("alt",)}


@pytest.fixture(scope="module")
def demo(tmp_path_factory) -> Path:
    from vid2sim.samples.demo_sample import generate_demo_sample

    folder = tmp_path_factory.mktemp("embedded_demo")
    generate_demo_sample(folder, seed=3, duration_s=6.0)
    return folder


def _fixes(demo: Path):
    return read_gps(demo / "demo.gpx").fixes


def embed(kind: str, demo: Path, out: Path, first_fix_s: float = 0.0) -> Path:
    """The demo video with the demo's GPS fixes inside in format ``kind``, the first fix at
    video time ``first_fix_s``."""
    fixes = _fixes(demo)
    t0 = fixes[0].t_utc_s - first_fix_s
    times = [f.t_utc_s - t0 for f in fixes]
    gaps = [*np.diff(times).tolist(), 1.0]
    video = demo / "demo.mp4"
    dst = out / f"{kind}.mp4"
    if kind == "gpmf-gps5":
        packets = [(t, d, rec.gps5_payload([f])) for t, d, f in zip(times, gaps, fixes, strict=True)]
        return rec.remux_with_telemetry(video, dst, "gpmf", packets)
    if kind == "gpmf-gps9":
        packets = [(times[i], sum(gaps[i:i + 2]), rec.gps9_payload(fixes[i:i + 2]))
                   for i in range(0, len(fixes), 2)]
        return rec.remux_with_telemetry(video, dst, "gpmf", packets)
    if kind == "nmea-track":
        packets = [(t, d, "\r\n".join(rec.nmea_sentences(f)).encode())
                   for t, d, f in zip(times, gaps, fixes, strict=True)]
        return rec.remux_with_telemetry(video, dst, "text", packets)
    if kind == "nmea-box":
        # the box has no packet clock: its first stamp is the first frame
        return rec.append_blackvue_box(rec.copy_video(video, dst), fixes, start_utc_s=t0)
    packets = [(t, d, rec.dji_cue(f).encode()) for t, d, f in zip(times, gaps, fixes, strict=True)]
    return rec.remux_with_telemetry(video, dst, "text", packets)


def _max_distance_m(a, b) -> float:
    assert np.array_equal(a.t_s, b.t_s)
    return float(np.hypot(a.x_m - b.x_m, a.y_m - b.y_m).max())


@pytest.mark.parametrize("kind", sorted(FIELDS))
def test_embedded_fixes_give_the_trajectory_of_the_same_fixes_in_a_file(kind, demo, tmp_path):
    """The fixes inside the video, first at video time 0.7 s, give the trajectory of the same
    fixes in a CSV placed with --gps-offset 0.7 (within 0.1 m), not the one at offset 0."""
    video = embed(kind, demo, tmp_path, first_fix_s=0.7)
    csv = rec.write_csv(tmp_path / "same.csv", _fixes(demo), FIELDS[kind])
    inside, separate = read_gps(video), read_gps(csv)
    assert len(inside.fixes) == len(separate.fixes) == len(_fixes(demo))
    # the container's clock: every fix at its packet's time
    assert inside.fixes[0].t_utc_s - inside.video_start_utc_s == pytest.approx(0.7, abs=1e-3)
    ego_in, _ = smooth_ego(inside)
    ego_file, _ = smooth_ego(separate, gps_offset_s=0.7)
    assert _max_distance_m(ego_in, ego_file) < 0.1
    ego_wrong, _ = smooth_ego(separate, gps_offset_s=0.0)
    common = np.intersect1d(ego_in.t_s, ego_wrong.t_s)
    moved = [np.hypot(ego_in.x_m[ego_in.t_s == t] - ego_wrong.x_m[ego_wrong.t_s == t],
                      ego_in.y_m[ego_in.t_s == t] - ego_wrong.y_m[ego_wrong.t_s == t])[0]
             for t in common]
    assert max(moved) > 5.0  # 0.7 s at 13 m/s: the clock is what places the fixes


def test_a_video_with_gps_builds_with_and_without_gps_option(demo, tmp_path):
    """`build VIDEO` and `build VIDEO --gps VIDEO` use the GPS inside; the ego matches the
    build from the same fixes in a CSV within 0.1 m; the scenario records the clock."""
    video = embed("gpmf-gps5", demo, tmp_path)
    csv = rec.write_csv(tmp_path / "same.csv", _fixes(demo), FIELDS["gpmf-gps5"])
    common = ["--camera", str(demo / "camera.yaml"), "--detections",
              str(demo / "detections.txt"), "--offline"]
    runs = {"inside": [], "explicit": ["--gps", str(video)],
            "csv": ["--gps", str(csv), "--gps-offset", "0"]}
    egos = {}
    for name, extra in runs.items():
        out = tmp_path / name
        assert main(["-q", "build", str(video), *common, *extra, "--out", str(out)]) == 0
        scenario = json.loads((out / "scenario.json").read_text())
        egos[name] = np.array([[p["t"], p["x"], p["y"]]
                               for p in scenario["ego"]["trajectory"]], float)
        clock = scenario["source"]["options"]["video_clock"]
        assert clock["clock"] == "container presentation times"
    for name in ("inside", "explicit"):
        assert egos[name].shape == egos["csv"].shape
        assert np.abs(egos[name][:, 0] - egos["csv"][:, 0]).max() < 1e-6
        assert np.hypot(*(egos[name][:, 1:] - egos["csv"][:, 1:]).T).max() < 0.1
    roles = [i["role"] for i in json.loads((tmp_path / "inside" / "scenario.json").read_text()
                                           )["source"]["inputs"]]
    assert roles[:2] == ["video", "gps"]


def test_find_telemetry_names_each_format(demo, tmp_path):
    kinds = {k: find_telemetry(embed(k, demo, tmp_path))[0].kind for k in FIELDS}
    assert kinds == {"gpmf-gps5": "gpmf", "gpmf-gps9": "gpmf", "nmea-track": "nmea-track",
                     "nmea-box": "nmea-box", "dji-cues": "subtitle-telemetry"}


# --------------------------------------------------------------------------- bad input


def test_a_telemetry_track_without_a_fix_is_one_error_line(demo, tmp_path, capsys, raised):
    fixes = _fixes(demo)
    packets = [(i * 1.0, 1.0, rec.gps5_payload(fixes[i:i + 1], fix_type=0)) for i in range(5)]
    video = rec.remux_with_telemetry(demo / "demo.mp4", tmp_path / "nolock.mp4", "gpmf", packets)
    with pytest.raises(FormatError):
        read_embedded(video)
    assert main(["trace", str(video), "--out", str(tmp_path / "ego.csv")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {video}: ") and raised == [FormatError]
    assert not (tmp_path / "ego.csv").exists()


def test_fixes_out_of_order_are_sorted_with_a_warning(demo, tmp_path):
    fixes = _fixes(demo)
    order = list(range(len(fixes)))
    order[2], order[3] = order[3], order[2]  # two sentences written out of order
    t0 = fixes[0].t_utc_s
    packets = [(fixes[i].t_utc_s - t0, 0.5, "\r\n".join(rec.nmea_sentences(fixes[i])).encode())
               for i in order]
    packets.sort(key=lambda p: p[0])
    swapped = [(packets[k][0], packets[k][1], packets[j][2]) for k, j in enumerate(order)]
    video = rec.remux_with_telemetry(demo / "demo.mp4", tmp_path / "swap.mp4", "text", swapped)
    trace = read_gps(video)
    assert any("not in time order" in w for w in trace.warnings)
    assert [f.t_utc_s for f in trace.fixes] == sorted(f.t_utc_s for f in trace.fixes)


def test_a_truncated_recording_is_one_error_line(demo, tmp_path, capsys, raised):
    video = embed("nmea-box", demo, tmp_path)
    cut = tmp_path / "cut.mp4"
    data = video.read_bytes()
    cut.write_bytes(data[: len(data) - 40])  # the gps box loses its end
    assert main(["trace", str(cut), "--out", str(tmp_path / "ego.csv")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {cut}: ") and raised == [FormatError]


def test_a_video_without_telemetry_as_gps_is_a_format_error(demo, tmp_path):
    video = rec.copy_video(demo / "demo.mp4", tmp_path / "plain.mp4")
    with pytest.raises(FormatError):
        read_gps(video)


def test_a_sidecar_srt_is_read_on_the_video_clock(demo, tmp_path):
    fixes = _fixes(demo)
    t0 = fixes[0].t_utc_s
    cues = []
    for k, f in enumerate(fixes):
        a, b = f.t_utc_s - t0, f.t_utc_s - t0 + 0.5
        cues.append(f"{k + 1}\n{_srt_time(a)} --> {_srt_time(b)}\n{rec.dji_cue(f)}\n")
    srt = tmp_path / "DJI_0001.SRT"
    srt.write_text("\n".join(cues))
    trace = read_gps(srt)
    assert trace.format == "srt" and len(trace.fixes) == len(fixes)
    ego_srt, _ = smooth_ego(trace)
    ego_csv, _ = smooth_ego(read_gps(rec.write_csv(tmp_path / "s.csv", fixes, ("alt",))),
                            gps_offset_s=0.0)
    assert _max_distance_m(ego_srt, ego_csv) < 0.1


def _srt_time(t: float) -> str:
    ms = round(t * 1000)
    return f"{ms // 3600000:02d}:{ms // 60000 % 60:02d}:{ms // 1000 % 60:02d},{ms % 1000:03d}"


def test_build_copies_nothing_half_written_on_a_bad_embedded_track(demo, tmp_path, capsys):
    fixes = _fixes(demo)
    packets = [(i * 1.0, 1.0, rec.gps5_payload(fixes[i:i + 1], fix_type=0)) for i in range(5)]
    video = rec.remux_with_telemetry(demo / "demo.mp4", tmp_path / "nolock.mp4", "gpmf", packets)
    out = tmp_path / "out"
    rc = main(["build", str(video), "--gps", str(video), "--detections",
               str(demo / "detections.txt"), "--offline", "--out", str(out)])
    assert rc == 2
    assert not out.exists() or not any(out.iterdir())
    shutil.rmtree(out, ignore_errors=True)
