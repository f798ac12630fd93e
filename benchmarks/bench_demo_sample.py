"""Benchmark of the demo sample generator: map loading, traffic simulation, frame rendering,
and the whole generation (render + encode + files).

Usage: ``python benchmarks/bench_demo_sample.py [--frames N] [--width W --height H]``.
Prints one line per stage; rendering is timed without the encoder so it measures the
renderer alone.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from vid2sim.samples import demo_sample as ds
from vid2sim.samples.render import DrawnVehicle, SceneRenderer


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=240)
    parser.add_argument("--width", type=int, default=960)
    parser.add_argument("--height", type=int, default=540)
    args = parser.parse_args(argv)

    t0 = time.perf_counter()
    route = ds.load_route()
    t_route = time.perf_counter() - t0
    print(f"route: {route.name}, {route.length_m:.0f} m, {len(route.way_ids)} OSM ways, "
          f"loaded in {t_route:.2f} s")

    t0 = time.perf_counter()
    traffic = ds.simulate_traffic(24.0, route.length_m)
    tracks = ds.traffic_to_enu(traffic, route.road)
    print(f"traffic simulation: {time.perf_counter() - t0:.2f} s "
          f"({len(traffic.t_s)} steps, {len(tracks)} vehicles)")

    cam = ds.demo_camera(args.width, args.height)
    renderer = SceneRenderer(cam, route.road, ds.demo_buildings(route.length_m))
    t_frames = np.arange(args.frames) * (24.0 / args.frames)

    def at(name: str, t: float) -> tuple[float, float, float]:
        tr = tracks[name]
        return (float(np.interp(t, traffic.t_s, tr.x_m)), float(np.interp(t, traffic.t_s, tr.y_m)),
                float(np.interp(t, traffic.t_s, tr.heading_rad)))

    t0 = time.perf_counter()
    for t in t_frames:
        ex, ey, eh = at("ego", t)
        es = float(np.interp(t, traffic.t_s, traffic.s_m["ego"]))
        vehicles = [DrawnVehicle(a.id, *at(a.id, t), a.length_m, a.width_m, a.height_m,
                                 a.color_bgr, a.style) for a in ds.ACTORS]
        renderer.render((ex, ey), eh, es, vehicles)
    dt = time.perf_counter() - t0
    print(f"render only: {args.frames} frames {args.width}x{args.height} in {dt:.2f} s = "
          f"{args.frames / dt:.0f} frames/s")

    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        sample = ds.generate_demo_sample(Path(tmp), width=args.width, height=args.height,
                                         route=route)
        dt = time.perf_counter() - t0
        print(f"whole sample (render, grain, encode, truth, files; route preloaded): "
              f"{dt:.2f} s for {sample.n_frames} frames; video "
              f"{sample.video.stat().st_size / 1e6:.1f} MB, {sample.n_detections} detections")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
