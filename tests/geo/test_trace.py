"""Ego trajectory: synthetic drives with ground truth (outliers, turns, stops), time alignment,
the ego.csv writer, and the accuracy bars on the real KITTI drive."""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vid2sim.app.gpsroad import run_trace
from vid2sim.app.inputs import Inputs
from vid2sim.app.settings import Settings
from vid2sim.base.errors import ImpossibleValueError, InconsistentInputError
from vid2sim.core.enu import EnuFrame
from vid2sim.core.records import GpsTrace, Origin
from vid2sim.core.tables import write_ego_csv
from vid2sim.geo.readers import read_gps
from vid2sim.geo.trace import smooth_ego
from vid2sim.samples.sample_gps import (
    HELSINKI,
    Segment,
    main,
    sample_fixes,
    simulate,
    write_sample_gpx,
)


def angle_diff(a, b):
    return np.angle(np.exp(1j * (np.asarray(a) - np.asarray(b))))


def run(fixes, **kw):
    return smooth_ego(GpsTrace(fixes=fixes, format="synthetic"), origin=HELSINKI, **kw)


# --------------------------------------------------------------------------- synthetic drives


def test_straight_drive_with_wild_fix_and_burst_rejected():
    truth = simulate([Segment(120.0)], v0_mps=15.0, heading0_rad=math.radians(30))
    outliers = {40: (900.0, -600.0), 80: (150.0, 20.0), 81: (160.0, 25.0), 82: (155.0, 15.0)}
    ego, stats = run(sample_fixes(truth, rate_hz=1.0, noise_m=3.0, outliers=outliers, seed=1))
    assert stats.n_rejected == 4
    tr = truth.at(ego.t_s)
    pos_err = np.hypot(ego.x_m - tr["x_m"], ego.y_m - tr["y_m"])
    assert pos_err.max() < 8.0  # the track never visits the outliers (150 m .. 1 km away)
    assert np.sqrt(np.mean(pos_err**2)) < 2.5
    assert np.sqrt(np.mean((ego.speed_mps - 15.0) ** 2)) < 0.6
    assert np.median(np.abs(angle_diff(ego.heading_rad, math.radians(30)))) < math.radians(2)
    assert stats.stationary == []  # never invents a stop
    assert stats.distance_m == pytest.approx(15.0 * 120.0, rel=0.03)


def test_left_turn_heading_is_counter_clockwise_from_east():
    # North-bound (heading +90 deg), then a 90 deg left turn: ends west-bound (180 deg).
    truth = simulate([Segment(20.0), Segment(12.0, 0.0, math.pi / 2 / 12.0), Segment(20.0)],
                     v0_mps=10.0, heading0_rad=math.pi / 2)
    ego, _ = run(sample_fixes(truth, rate_hz=1.0, noise_m=2.0, seed=3))
    start, end = ego.t_s < 15, ego.t_s > 37
    assert np.median(np.abs(angle_diff(ego.heading_rad[start], math.pi / 2))) < math.radians(3)
    assert np.median(np.abs(angle_diff(ego.heading_rad[end], math.pi))) < math.radians(3)
    # Moving west means x decreases: the heading convention matches the positions.
    assert ego.x_m[-1] < ego.x_m[ego.t_s.searchsorted(35)] - 100
    tr = truth.at(ego.t_s)
    assert np.sqrt(np.mean(angle_diff(ego.heading_rad, tr["heading_rad"]) ** 2)) < math.radians(5)


def stop_and_go():
    return simulate([Segment(10.0, 1.2), Segment(30.0), Segment(6.0, -2.0), Segment(30.0),
                     Segment(8.0, 1.5), Segment(30.0)], v0_mps=0.0, heading0_rad=math.radians(-40))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_stop_and_go_stationary_period_stays_at_zero(seed):
    truth = stop_and_go()  # stopped from t = 46 s to t = 76 s
    outliers = {60: (-70.0, 90.0), 100: (120.0, 0.0)}
    ego, stats = run(sample_fixes(truth, rate_hz=1.0, noise_m=3.0, outliers=outliers,
                                  seed=seed))
    assert stats.n_rejected >= 2
    inner = (ego.t_s >= 48.0) & (ego.t_s <= 74.0)
    assert np.all(ego.speed_mps[inner] == 0.0)  # exactly 0: no noise-driven creeping
    assert np.ptp(ego.x_m[inner]) == 0.0 and np.ptp(ego.y_m[inner]) == 0.0
    assert np.ptp(ego.heading_rad[inner]) == 0.0  # held, not noise-driven
    assert abs(angle_diff(ego.heading_rad[inner][0], math.radians(-40))) < math.radians(5)
    assert any(a <= 48.0 and b >= 74.0 for a, b in stats.stationary)
    # ...and the stop is where the car really stood.
    stop_truth = truth.at(np.array([60.0]))
    assert math.hypot(ego.x_m[inner][0] - stop_truth["x_m"][0],
                      ego.y_m[inner][0] - stop_truth["y_m"][0]) < 2.5
    tr = truth.at(ego.t_s)
    assert np.sqrt(np.mean((ego.speed_mps - tr["speed_mps"]) ** 2)) < 0.7
    moving = tr["speed_mps"] > 3.0
    assert np.all(ego.speed_mps[moving] > 0.5)  # never invents a stop while driving


def test_reported_doppler_zero_speed_makes_a_stop():
    truth = stop_and_go()
    fixes = sample_fixes(truth, rate_hz=1.0, noise_m=4.0, seed=7, with_speed=True)
    ego, _ = run(fixes)
    inner = (ego.t_s >= 47.0) & (ego.t_s <= 75.0)
    assert np.all(ego.speed_mps[inner] == 0.0)
    tr = truth.at(ego.t_s)
    # Fused Doppler speed beats positions alone.
    ego_pos, _ = run([dataclasses.replace(f, speed_mps=None, course_deg=None) for f in fixes])
    rmse_fused = np.sqrt(np.mean((ego.speed_mps - tr["speed_mps"]) ** 2))
    rmse_pos = np.sqrt(np.mean((ego_pos.speed_mps - tr["speed_mps"]) ** 2))
    assert rmse_fused < 0.3 and rmse_fused < rmse_pos


def test_parked_car_never_moves():
    truth = simulate([Segment(60.0)], v0_mps=0.0, heading0_rad=1.0)
    ego, stats = run(sample_fixes(truth, rate_hz=1.0, noise_m=3.0, seed=4))
    assert np.all(ego.speed_mps == 0.0)
    assert stats.distance_m == 0.0
    assert any("never moves" in w for w in stats.warnings)


def test_wild_first_fix_does_not_capture_the_track_or_the_origin():
    truth = simulate([Segment(60.0)], v0_mps=12.0, heading0_rad=0.0)
    fixes = sample_fixes(truth, rate_hz=1.0, noise_m=2.0, outliers={0: (5000.0, 3000.0)}, seed=5)
    ego, stats = smooth_ego(GpsTrace(fixes=fixes, format="synthetic"))
    assert stats.n_rejected == 1
    assert ego.origin.lat == fixes[1].lat_deg and ego.origin.lon == fixes[1].lon_deg
    assert ego.t_s[0] == pytest.approx(1.0)  # the first accepted fix is 1 s after the wild one
    assert abs(ego.x_m[0]) < 15 and abs(ego.y_m[0]) < 15


def test_precise_10hz_trace_follows_acceleration():
    truth = simulate([Segment(5.0, 3.0), Segment(5.0, -2.0), Segment(5.0, 0.0, 0.2)],
                     v0_mps=5.0, heading0_rad=2.0)
    ego, stats = run(sample_fixes(truth, rate_hz=10.0, noise_m=0.05, seed=6))
    tr = truth.at(ego.t_s)
    assert np.sqrt(np.mean((ego.speed_mps - tr["speed_mps"]) ** 2)) < 0.15
    assert stats.noise_m == pytest.approx(0.05, rel=0.4)


def test_gaps_are_reported():
    truth = simulate([Segment(100.0)], v0_mps=10.0)
    fixes = sample_fixes(truth, rate_hz=1.0, noise_m=1.0, seed=8)
    fixes = fixes[:40] + fixes[55:]
    _, stats = run(fixes)
    assert len(stats.gaps) == 1
    assert stats.gaps[0] == pytest.approx((39.0, 16.0))


@settings(max_examples=15, deadline=None)
@given(segs=st.lists(st.tuples(st.floats(2.0, 20.0), st.floats(-2.0, 2.0), st.floats(-0.2, 0.2)),
                     min_size=1, max_size=5),
       v0=st.floats(0.0, 20.0), noise=st.floats(0.1, 5.0), rate=st.sampled_from([1.0, 5.0]),
       seed=st.integers(0, 2**16))
def test_output_invariants_property(segs, v0, noise, rate, seed):
    truth = simulate([Segment(*s) for s in segs], v0_mps=v0, dt=0.05)
    fixes = sample_fixes(truth, rate_hz=rate, noise_m=noise, seed=seed)
    if len(fixes) < 2:
        return
    ego, stats = run(fixes, rate_hz=10.0)
    n = len(ego.t_s)
    assert n == stats.n_samples and n >= 1
    for a in (ego.x_m, ego.y_m, ego.heading_rad, ego.speed_mps, ego.lat_deg, ego.lon_deg):
        assert len(a) == n and np.all(np.isfinite(a))
    assert np.all(ego.speed_mps >= 0.0)
    assert np.all(np.abs(ego.heading_rad) <= math.pi + 1e-12)
    assert np.allclose(np.diff(ego.t_s), 0.1)
    assert 0 <= stats.n_rejected < len(fixes)
    for a, b in stats.stationary:
        inside = (ego.t_s >= a) & (ego.t_s <= b)
        assert np.all(ego.speed_mps[inside] == 0.0)


# --------------------------------------------------------------------------- time alignment


def short_trace(video_start=None):
    truth = simulate([Segment(10.0)], v0_mps=10.0)
    fixes = sample_fixes(truth, rate_hz=1.0, noise_m=0.5, seed=9, t0_utc_s=1e9)
    return GpsTrace(fixes=fixes, format="synthetic", video_start_utc_s=video_start)


def test_first_fix_is_time_zero_without_a_clock():
    ego, stats = smooth_ego(short_trace(), rate_hz=4.0)
    assert ego.t_s[0] == 0.0 and ego.t_s[-1] == pytest.approx(10.0)
    assert np.allclose(np.diff(ego.t_s), 0.25)
    assert stats.t0_utc_s == 1e9 and "first fix = first frame" in stats.time_alignment


def test_file_clock_and_offset_override():
    ego, stats = smooth_ego(short_trace(video_start=1e9 + 2.5), rate_hz=2.0)
    assert stats.first_fix_t_s == pytest.approx(-2.5)
    assert ego.t_s[0] == pytest.approx(-2.5) and ego.t_s[-1] == pytest.approx(7.5)
    ego2, stats2 = smooth_ego(short_trace(video_start=1e9 + 2.5), rate_hz=2.0, gps_offset_s=1.0)
    assert ego2.t_s[0] == pytest.approx(1.0) and stats2.first_fix_t_s == pytest.approx(1.0)
    assert "--gps-offset" in stats2.time_alignment
    # Same motion, shifted clock.
    assert np.allclose(ego2.x_m[:10], ego.x_m[:10], atol=1e-6)


def test_grid_lies_on_multiples_of_the_period():
    tr = short_trace(video_start=1e9 - 0.33)  # first fix at video time 0.33 s
    ego, _ = smooth_ego(tr, rate_hz=10.0)
    assert ego.t_s[0] == pytest.approx(0.4)
    assert np.allclose(ego.t_s * 10, np.round(ego.t_s * 10))


def test_origin_argument_and_latlon_consistency():
    o = Origin(60.17, 24.93, 5.0)
    ego, _ = smooth_ego(short_trace(), origin=o)
    assert ego.origin == o
    enu = EnuFrame(o).to_enu(ego.lat_deg, ego.lon_deg, 0.0)
    assert np.allclose(enu[:, 0], ego.x_m, atol=0.01) and np.allclose(enu[:, 1], ego.y_m, atol=0.01)


def test_errors():
    tr = short_trace()
    with pytest.raises(InconsistentInputError):  # one fix is no trajectory
        smooth_ego(GpsTrace(fixes=tr.fixes[:1], format="x"))
    with pytest.raises(ImpossibleValueError):
        smooth_ego(tr, rate_hz=0.0)


# --------------------------------------------------------------------------- writer, run_trace


def test_write_ego_csv_format_and_determinism(tmp_path):
    ego, _ = smooth_ego(short_trace(), rate_hz=2.0)
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    write_ego_csv(ego, a)
    ego2, _ = smooth_ego(short_trace(), rate_hz=2.0)
    write_ego_csv(ego2, b)
    assert a.read_bytes() == b.read_bytes()
    lines = a.read_text().splitlines()
    assert lines[0] == "t_s,lat,lon,x_m,y_m,heading_rad,speed_mps"
    assert len(lines) == len(ego.t_s) + 1
    cells = lines[1].split(",")
    assert [len(c.split(".")[1]) for c in cells] == [3, 8, 8, 3, 3, 5, 3]
    assert not re.search(r"(^|,)-0\.0+(,|$)", a.read_text(), re.MULTILINE)  # no negative zero


def test_write_ego_csv_is_atomic(tmp_path):
    ego, _ = smooth_ego(short_trace(), rate_hz=2.0)
    out = tmp_path / "ego.csv"
    out.write_text("previous\n")
    bad = dataclasses.replace(ego, speed_mps=ego.speed_mps[:-1])  # length mismatch
    with pytest.raises(ValueError):
        write_ego_csv(bad, out)
    assert out.read_text() == "previous\n"
    assert list(tmp_path.iterdir()) == [out]  # no temporary file left behind


def test_sample_gpx_and_run_trace(tmp_path):
    gpx = write_sample_gpx(tmp_path / "sample.gpx")
    again = write_sample_gpx(tmp_path / "again.gpx")
    assert gpx.read_bytes() == again.read_bytes()  # deterministic
    tr = read_gps(gpx)
    assert tr.format == "gpx" and 200 < len(tr.fixes) < 400
    lat = np.array([f.lat_deg for f in tr.fixes])
    assert abs(np.median(lat) - 60.1699) < 0.02
    summary = run_trace(Inputs(gps=gpx), tmp_path / "ego.csv", Settings(rate_hz=5.0))
    for word in ("format:", "gpx", "fixes:", "duration:", "distance:", "speed:", "gaps",
                 "rejected", "time:", str(tmp_path / "ego.csv")):
        assert word in summary
    assert (tmp_path / "ego.csv").read_text().startswith("t_s,lat,lon")


def test_sample_gps_module_entry(tmp_path, capsys):
    assert main([]) == 2
    assert main([str(tmp_path / "s.gpx")]) == 0
    assert (tmp_path / "s.gpx").read_text().startswith("<?xml")
    assert "wrote" in capsys.readouterr().out


# --------------------------------------------------------------------------- real data


def kitti_vf(kitti_raw_dir: Path) -> np.ndarray:
    files = sorted((kitti_raw_dir / "oxts" / "data").glob("*.txt"))
    return np.array([float(f.read_text().split()[8]) for f in files])


def speed_rmse_vs_vf(ego, stats, t_utc, vf) -> float:
    """RMSE of the derived speed against OXTS vf at the OXTS times inside the trajectory."""
    t = t_utc - stats.t0_utc_s
    m = (t >= ego.t_s[0]) & (t <= ego.t_s[-1])
    return float(np.sqrt(np.mean((np.interp(t[m], ego.t_s, ego.speed_mps) - vf[m]) ** 2)))


def test_kitti_speed_from_positions_only(kitti_raw_dir):
    """Issue 2 bar: lat/lon/time only at 10 Hz -> RMSE vs vf <= 0.3 m/s."""
    trace = read_gps(kitti_raw_dir)
    vf = kitti_vf(kitti_raw_dir)
    t_utc = np.array([f.t_utc_s for f in trace.fixes])
    bare = [dataclasses.replace(f, alt_m=None, speed_mps=None, course_deg=None, accuracy_m=None)
            for f in trace.fixes]
    ego, stats = smooth_ego(dataclasses.replace(trace, fixes=bare), rate_hz=10.0)
    rmse = speed_rmse_vs_vf(ego, stats, t_utc, vf)
    print(f"KITTI 10 Hz positions-only speed RMSE vs vf: {rmse:.3f} m/s")
    assert rmse <= 0.3
    assert stats.n_rejected == 0 and stats.stationary == []
    # Heading against the OXTS yaw (0 = east, counter-clockwise), the same convention.
    files = sorted((kitti_raw_dir / "oxts" / "data").glob("*.txt"))
    yaw = np.array([float(f.read_text().split()[5]) for f in files])
    t = t_utc - stats.t0_utc_s
    m = (t >= ego.t_s[0]) & (t <= ego.t_s[-1])
    h = np.interp(t[m], ego.t_s, np.unwrap(ego.heading_rad))
    assert np.median(np.abs(angle_diff(h, yaw[m]))) < math.radians(3)


def test_kitti_speed_1hz_with_3m_noise(kitti_raw_dir):
    """Issue 2 bar: subsampled to 1 Hz, 3 m Gaussian noise per fix -> RMSE <= 1.0 m/s.

    The drive is only 10.8 s long (11 fixes at 1 Hz), so one noise draw decides a lot; the
    bar is checked on the mean over 10 seeded draws (each draw printed)."""
    trace = read_gps(kitti_raw_dir)
    vf = kitti_vf(kitti_raw_dir)
    t_utc = np.array([f.t_utc_s for f in trace.fixes])
    sub = trace.fixes[::10]
    frame = EnuFrame(Origin(sub[0].lat_deg, sub[0].lon_deg, 0.0))
    enu = frame.to_enu([f.lat_deg for f in sub], [f.lon_deg for f in sub], 0.0)
    rmses = []
    for seed in range(10):
        rng = np.random.default_rng(seed)
        noisy = enu.copy()
        noisy[:, :2] += rng.normal(0.0, 3.0, (len(sub), 2))
        lat, lon, _ = frame.to_geodetic(noisy)
        fixes = [dataclasses.replace(f, lat_deg=float(a), lon_deg=float(b), alt_m=None,
                                     speed_mps=None, course_deg=None, accuracy_m=None)
                 for f, a, b in zip(sub, lat, lon, strict=True)]
        ego, stats = smooth_ego(dataclasses.replace(trace, fixes=fixes), rate_hz=10.0)
        rmses.append(speed_rmse_vs_vf(ego, stats, t_utc, vf))
    print("KITTI 1 Hz + 3 m noise speed RMSE per seed:", " ".join(f"{r:.2f}" for r in rmses),
          f"mean {np.mean(rmses):.3f} median {np.median(rmses):.3f}")
    assert np.mean(rmses) <= 1.0
    assert np.median(rmses) <= 1.0


# --------------------------------------------------------------------------- one drive, gaps


def test_fixes_alternating_between_two_cities_are_an_input_error():
    # Half the fixes 1,820 km away: no car drives that; the error names the first jump.
    fixes = sample_fixes(simulate([Segment(60.0)], v0_mps=10.0), rate_hz=1.0, noise_m=2.0,
                         seed=4)
    far = [dataclasses.replace(f, lat_deg=51.5, lon_deg=-0.12) if i % 2 else f
           for i, f in enumerate(fixes)]
    with pytest.raises(InconsistentInputError,
                       match=r"fix 2 \(in time order\) is 18\d\d\.\d km from fix 1"):
        run(far)


def test_two_drives_in_one_file_are_an_input_error():
    a = sample_fixes(simulate([Segment(60.0)], v0_mps=10.0), rate_hz=1.0, noise_m=2.0, seed=5)
    b = [dataclasses.replace(f, t_utc_s=f.t_utc_s + 61.0, lat_deg=f.lat_deg - 8.0)
         for f in a[:20]]
    with pytest.raises(InconsistentInputError, match="fix 62 "):
        run(a + b)


def test_a_few_wild_fixes_far_away_are_outliers_not_an_error():
    fixes = sample_fixes(simulate([Segment(300.0)], v0_mps=10.0), rate_hz=1.0, noise_m=2.0,
                         seed=6)
    fixes[100] = dataclasses.replace(fixes[100], lat_deg=0.0, lon_deg=0.0)  # "null island"
    fixes[200] = dataclasses.replace(fixes[200], lat_deg=fixes[200].lat_deg + 1.0)
    ego, stats = run(fixes)
    assert stats.n_rejected == 2
    assert np.all(np.abs(ego.y_m) < 50.0)  # the drive is due east: nothing pulled away


@pytest.mark.parametrize("bias_m", [0.0, 30.0])
def test_a_long_gap_while_parked_invents_no_motion(bias_m):
    # A 10-minute gap in the middle of a 15-minute stop, fixes wandering as a parked phone's
    # do (30 m Gauss-Markov bias): the old smoother drove 560 m back and forth through it.
    truth = simulate([Segment(10.0, 1.0), Segment(290.0), Segment(10.0, -1.0), Segment(900.0),
                      Segment(10.0, 1.0), Segment(290.0)], dt=0.05)
    fixes = sample_fixes(truth, rate_hz=1.0, noise_m=3.0, bias_m=bias_m, seed=3)
    t = np.array([f.t_utc_s for f in fixes]) - fixes[0].t_utc_s
    fixes = [f for f, ti in zip(fixes, t, strict=True) if not 500.0 < ti < 1100.0]
    ego, stats = run(fixes)
    inside = (ego.t_s > 500.0) & (ego.t_s < 1100.0)
    x, y = ego.x_m[inside], ego.y_m[inside]
    chord = math.hypot(x[-1] - x[0], y[-1] - y[0])
    # straight from one end to the other, never back: the path is the chord
    assert np.hypot(np.diff(x), np.diff(y)).sum() == pytest.approx(chord, abs=0.5)
    assert np.ptp(np.unwrap(ego.heading_rad[inside])) < 1e-9  # no heading flips
    assert ego.speed_mps[inside].max() < 0.2
    assert any("GPS gap of 600 s at t=500.0 s" in w for w in stats.warnings)
    assert any("GPS gap of 600 s" in a for a in stats.assumptions)
    assert "GPS gap of 600 s" in "\n".join(format_summary_lines(stats))


def format_summary_lines(stats):
    from vid2sim.geo.trace import format_summary

    return format_summary(stats).splitlines()


def test_a_tunnel_gap_is_crossed_at_constant_speed():
    truth = simulate([Segment(200.0)], v0_mps=15.0, heading0_rad=0.3)
    fixes = sample_fixes(truth, rate_hz=1.0, noise_m=2.0, seed=7)
    fixes = fixes[:80] + fixes[140:]  # 61 s between fixes
    ego, stats = run(fixes)
    inside = (ego.t_s > 80.0) & (ego.t_s < 139.0)
    assert np.all(np.abs(ego.speed_mps[inside] - 15.0) < 0.5)
    tr = truth.at(ego.t_s[inside])
    assert np.hypot(ego.x_m[inside] - tr["x_m"], ego.y_m[inside] - tr["y_m"]).max() < 5.0
    assert stats.gaps == [(79.0, 61.0)]  # fixes 79 and 140 bracket it
