"""Speed of the ego-trajectory stage: ``smooth_ego`` on a one-hour 1 Hz drive (and read_gps on
its GPX), printed as fixes per second.

    python benchmarks/bench_trace.py [--hours 1] [--rate 1] [--repeat 3]

The drive is synthetic (stop-and-go city driving with turns, 3 m noise, a few outliers) so the
figure does not depend on any data set.
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from vid2sim.core.records import GpsTrace
from vid2sim.geo.readers import read_gps
from vid2sim.geo.trace import smooth_ego
from vid2sim.samples.sample_gps import HELSINKI, Segment, sample_fixes, simulate


def city_drive(duration_s: float, seed: int = 0) -> list[Segment]:
    """Repeating blocks of pull-away, cruise, a turn, braking and a stop at a light."""
    rng = np.random.default_rng(seed)
    segs: list[Segment] = []
    total = 0.0
    while total < duration_s:
        v = float(rng.uniform(8, 16))
        turn = float(rng.choice([-1, 1])) * math.pi / 2
        block = [Segment(v / 1.5, 1.5), Segment(float(rng.uniform(20, 60))),
                 Segment(10.0, 0.0, turn / 10.0), Segment(float(rng.uniform(10, 40))),
                 # Braking 1 s longer than needed: the speed clamps at exactly 0.
                 Segment(v / 2.0 + 1.0, -2.0), Segment(float(rng.uniform(5, 40)))]
        segs += block
        total += sum(s.duration_s for s in block)
    return segs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=1.0)
    ap.add_argument("--rate", type=float, default=1.0, help="GPS fix rate [Hz]")
    ap.add_argument("--out-rate", type=float, default=10.0, help="trajectory rate [Hz]")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()

    truth = simulate(city_drive(args.hours * 3600.0), dt=0.05)
    n = int(args.hours * 3600 * args.rate)
    outliers = {i: (150.0, -80.0) for i in range(100, n, 500)}
    fixes = sample_fixes(truth, HELSINKI, rate_hz=args.rate, noise_m=3.0, outliers=outliers,
                         seed=1)[:n]
    trace = GpsTrace(fixes=fixes, format="synthetic")
    times = []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        ego, stats = smooth_ego(trace, rate_hz=args.out_rate)
        times.append(time.perf_counter() - t0)
    best = min(times)
    tr = truth.at(ego.t_s)
    still = np.concatenate(([0], (truth.speed_mps < 1e-6).astype(np.int8), [0]))
    starts, ends = np.flatnonzero(np.diff(still) == 1), np.flatnonzero(np.diff(still) == -1)
    n_true_stops = int(np.sum((ends - starts) * (truth.t_s[1] - truth.t_s[0]) >= 1.5))
    rmse = float(np.sqrt(np.mean((ego.speed_mps - tr["speed_mps"]) ** 2)))
    print(f"smooth_ego: {len(fixes)} fixes ({args.hours:g} h at {args.rate:g} Hz) -> "
          f"{stats.n_samples} samples at {args.out_rate:g} Hz")
    print(f"  best of {args.repeat}: {best:.2f} s = {len(fixes) / best:,.0f} fixes/s "
          f"(all runs: {', '.join(f'{t:.2f}' for t in times)} s)")
    print(f"  rejected {stats.n_rejected} (injected {len(outliers)}), stops "
          f"{len(stats.stationary)} (true {n_true_stops}), speed RMSE vs truth {rmse:.2f} m/s")

    import gpxpy.gpx

    gpx = gpxpy.gpx.GPX()
    seg = gpxpy.gpx.GPXTrackSegment()
    seg.points = [gpxpy.gpx.GPXTrackPoint(f.lat_deg, f.lon_deg, elevation=f.alt_m,
                                          time=datetime.fromtimestamp(f.t_utc_s, UTC))
                  for f in fixes]
    track = gpxpy.gpx.GPXTrack()
    track.segments.append(seg)
    gpx.tracks.append(track)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.gpx"
        path.write_text(gpx.to_xml())
        t0 = time.perf_counter()
        read_gps(path)
        dt = time.perf_counter() - t0
    print(f"read_gps (GPX, {path.name}): {dt:.2f} s = {len(fixes) / dt:,.0f} fixes/s")


if __name__ == "__main__":
    main()
