"""Synthetic drives on a real road network, with their ground truth, for tests, benchmarks and
the README's sample trace: shortest paths between junctions driven at urban speeds, sampled
by a GPS receiver with Gaussian noise and outliers."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import networkx as nx
import numpy as np

from vid2sim.geo.mapmatch import merge_ways
from vid2sim.geo.osm import RoadNetwork


@dataclass(slots=True)
class SimulatedDrive:
    """A drive simulated along a shortest path, with its ground truth.

    :param route_edges: true directed edges in travel order, from the first to the last fix
    :param true_ways: their way ids, consecutive repeats merged
    :param t_s, x_m, y_m: noisy 1 Hz fixes [s, m]
    :param true_way_id: way under the true position of each fix
    :param is_outlier: fixes displaced by 30-80 m
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
                   rate_hz: float = 1.0, random_phase: bool = True) -> SimulatedDrive:
    """Drive the shortest path between two random junctions of ``net`` and record noisy fixes.

    Speed: a cruise speed drawn from 7-13 m/s (25-47 km/h, urban), 4 m/s through turns
    sharper than 45 degrees, accelerating and braking at most 1.5 m/s^2; with ``stop_s`` > 0
    the car stops halfway and stands still that long. The first fix falls at a random point
    of the first second of driving (``random_phase``), not exactly on the start junction.
    Noise: Gaussian, ``noise_m`` per axis; ``outlier_share`` of the fixes are
    instead displaced 30-80 m in a random direction.
    """
    graph = net.graph()
    nodes = np.unique(np.concatenate([net.edge_u, net.edge_v]))
    for _ in range(10000):
        a, b = (int(v) for v in rng.choice(nodes, 2, replace=False))
        try:
            path = nx.dijkstra_path(graph, a, b, weight="length")
        except nx.NetworkXNoPath:
            continue
        edges = [int(graph[p][q]["edge"]) for p, q in itertools.pairwise(path)]
        total = float(net.edge_length_m[edges].sum())
        if min_length_m <= total <= max_length_m:
            break
    else:  # pragma: no cover - the map is too small for the requested lengths
        raise ValueError("no route of the requested length in this network")
    pts = np.vstack([net.edge_xy[edges[0]]] + [net.edge_xy[e][1:] for e in edges[1:]])
    seg = np.hypot(*np.diff(pts, axis=0).T)
    keep = np.concatenate([[True], seg > 1e-6])
    pts = pts[keep]
    s_pts = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
    # speed limit profile along a 1 m grid: slow down around sharp turns
    grid = np.arange(0.0, total, 1.0)
    gx, gy = np.interp(grid, s_pts, pts[:, 0]), np.interp(grid, s_pts, pts[:, 1])
    head = np.unwrap(np.arctan2(np.gradient(gy), np.gradient(gx)))
    turn = np.abs(np.interp(grid + 10, grid, head) - np.interp(grid - 10, grid, head))
    cruise = float(rng.uniform(7.0, 13.0))
    v_grid = np.where(turn > math.radians(45), 4.0, cruise)
    if stop_s > 0:
        v_grid[int(total / 2)] = 0.3  # creep to the stop line, then stand
    # comfortable acceleration / braking limit (1.5 m/s^2): v^2 <= v0^2 + 2 a ds
    for order in (slice(None), slice(None, None, -1)):
        v = v_grid[order]
        for k in range(1, v.size):
            v[k] = min(v[k], math.sqrt(v[k - 1] ** 2 + 2 * 1.5 * 1.0))
    dt = 1.0 / rate_hz
    # the receiver's 1 Hz clock does not know where the route begins: the first fix falls
    # anywhere within the first second of driving
    s = float(rng.uniform(0.0, v_grid[0] * dt)) if random_phase else 0.0
    t, s_list, t_list = 0.0, [], []
    stopped = stop_s <= 0
    while s < total:
        s_list.append(s)
        t_list.append(t)
        if not stopped and s >= total / 2:
            stopped = True
            for _ in range(int(stop_s * rate_hz)):
                t += dt
                s_list.append(s)
                t_list.append(t)
        s += float(np.interp(s, grid, v_grid)) * dt
        t += dt
    s_true = np.array(s_list)
    x = np.interp(s_true, s_pts, pts[:, 0])
    y = np.interp(s_true, s_pts, pts[:, 1])
    ends = np.cumsum(net.edge_length_m[edges])
    pos = np.minimum(np.searchsorted(ends, s_true, side="right"), len(edges) - 1)
    true_way = net.edge_way_id[np.asarray(edges)[pos]]
    n = len(s_true)
    x = x + rng.normal(0.0, noise_m, n)
    y = y + rng.normal(0.0, noise_m, n)
    out = rng.random(n) < outlier_share
    r, ang = rng.uniform(30.0, 80.0, n), rng.uniform(-math.pi, math.pi, n)
    x = np.where(out, np.interp(s_true, s_pts, pts[:, 0]) + r * np.cos(ang), x)
    y = np.where(out, np.interp(s_true, s_pts, pts[:, 1]) + r * np.sin(ang), y)
    # the driven sequence is what lies between the first and the last fix: a way the car
    # entered after its last fix was recorded cannot be known
    driven = edges[int(pos[0]):int(pos[-1]) + 1]
    ways = merge_ways([], [driven], net.edge_way_id)
    driven_start = float(ends[int(pos[0])] - net.edge_length_m[edges[int(pos[0])]])
    return SimulatedDrive(driven, ways, np.array(t_list), x, y, true_way, out, total,
                          s_true - driven_start)
