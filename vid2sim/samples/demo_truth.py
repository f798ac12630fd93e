"""Reading the demo sample's truth back: the true scenario, and a built scenario scored against it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from vid2sim.core.enu import EnuFrame
from vid2sim.core.records import Origin
from vid2sim.core.scenario import Actor, Ego, Road, Scenario, Source, Trajectory

# --------------------------------------------------------------------------- truth reader


def truth_scenario(truth_path: Path) -> Scenario:
    """The ground truth of a sample as a :class:`~vid2sim.core.scenario.Scenario` (to compare with
    what ``vid2sim build`` recovers)."""
    data = json.loads(Path(truth_path).read_text(encoding="utf-8"))
    o = data["origin"]

    def traj(points: list[dict]) -> Trajectory:
        return Trajectory.from_json(points)

    r = data["road"]
    road = Road(id=r["id"], name=r["name"], highway=r["highway"], source=r["source"],
                osm_way_ids=r["osm_way_ids"], lanes=r["lanes"], lane_width_m=r["lane_width_m"],
                centerline=np.asarray(r["centerline"]))
    ego = data["ego"]
    return Scenario(
        origin=Origin(o["lat"], o["lon"], o["alt"]), roads=[road],
        ego=Ego(ego["length_m"], ego["width_m"], ego["height_m"], traj(ego["trajectory"])),
        actors=[Actor(a["id"], a["category"], a["length_m"], a["width_m"], a["height_m"],
                      traj(a["trajectory"])) for a in data["actors"]],
        camera=dict(data["camera"]),
        source=Source(inputs=[{"name": Path(truth_path).name}], tool_version="demo truth",
                      assumptions=["ground truth of the synthetic demo sample"]))


def compare_to_truth(built: Scenario, truth_path: Path) -> dict:
    """How far a built scenario is from the sample's truth (both frames reconciled through
    WGS-84, since a build picks its own ENU origin).

    Returns
    -------
    dict
        ``ego``: RMS errors over the truth's frame times: ``along_m`` and ``cross_m`` (in the
        true ego frame), ``heading_deg``, ``speed_mps``; ``actors``: per built actor, the
        true actor nearest on average over the built actor's time span, with ``mean_m`` and
        ``max_m`` position errors (footprint centres) and the span ``t0_s``, ``t1_s``.
    """
    truth = truth_scenario(truth_path)
    from_built, to_truth = EnuFrame(built.origin), EnuFrame(truth.origin)

    def in_truth_frame(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        lat, lon, _ = from_built.to_geodetic(np.column_stack((x, y)))
        p = to_truth.to_enu(lat, lon)
        return p[:, 0], p[:, 1]

    true_ego = truth.ego.trajectory
    t = true_ego.t[(true_ego.t >= built.ego.trajectory.t[0])
                   & (true_ego.t <= built.ego.trajectory.t[-1])]
    true_now = true_ego.state_at(t)
    est = built.ego.trajectory.state_at(t)
    # A heading rotation between frames with different origins is below 1e-4 deg at 1 km:
    # headings are compared directly.
    bx, by = in_truth_frame(est["x"], est["y"])
    h = true_now["heading"]
    dx, dy = bx - true_now["x"], by - true_now["y"]
    along = dx * np.cos(h) + dy * np.sin(h)
    cross = -dx * np.sin(h) + dy * np.cos(h)
    dh = np.angle(np.exp(1j * (est["heading"] - h)))

    def rms(a: np.ndarray) -> float:
        return float(np.sqrt(np.mean(np.square(a)))) if len(a) else float("nan")

    actors = []
    for a in built.actors:
        ax, ay = in_truth_frame(a.trajectory.x, a.trajectory.y)
        best = None
        for ta in truth.actors:
            st = ta.trajectory.state_at(a.trajectory.t)
            err = np.hypot(st["x"] - ax, st["y"] - ay)
            if best is None or err.mean() < best[1]:
                best = (ta.id, float(err.mean()), float(err.max()))
        actors.append({"id": a.id, "truth_id": best[0] if best else None,
                       "mean_m": best[1] if best else float("nan"),
                       "max_m": best[2] if best else float("nan"),
                       "t0_s": float(a.trajectory.t[0]), "t1_s": float(a.trajectory.t[-1])})
    return {"ego": {"along_m": rms(along), "cross_m": rms(cross),
                    "heading_deg": float(np.degrees(rms(dh))),
                    "speed_mps": rms(est["speed"] - true_now["speed"])},
            "actors": actors}
