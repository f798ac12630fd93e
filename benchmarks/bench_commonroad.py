"""The CommonRoad export of built scenarios: counts, position error, CPU time.

    python benchmarks/bench_commonroad.py path/scenario.json [...]

For each scenario: actors, dynamic obstacles and their states, lanelets against the
cross-sections' lanes, the largest distance of any obstacle state from scenario.json's
position at that time (read back with commonroad-io's XML reader), the export's CPU seconds
(imports excluded: a warm-up export runs first) and the file's size.
"""

from __future__ import annotations

import json
import resource
import sys
import tempfile
from pathlib import Path

import numpy as np
from commonroad.common.reader.file_reader_xml import XMLFileReader

from vid2sim.core import scenario as scenario_io
from vid2sim.export.commonroad import write_commonroad


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def report(path: str, work: Path) -> None:
    sc = scenario_io.load(path)
    write_commonroad(sc, work / "warm")
    before = _cpu()
    write_commonroad(sc, work / "cr")
    cpu = _cpu() - before
    cr, _ = XMLFileReader(str(work / "cr" / "scenario.xml")).open()
    ids = json.loads((work / "cr" / "ids.json").read_text())
    worst, states = 0.0, 0
    for actor in sc.actors:
        ob = cr.obstacle_by_id(ids["actors"][actor.id])
        st = [ob.initial_state, *(ob.prediction.trajectory.state_list if ob.prediction else [])]
        t = ids["t0_s"] + np.array([s.time_step for s in st]) * cr.dt
        want = actor.trajectory.state_at(t)
        got = np.array([s.position for s in st])
        worst = max(worst, float(np.hypot(got[:, 0] - want["x"], got[:, 1] - want["y"]).max()))
        states += len(st)
    lanes = sum(len(r.layout()) for r in sc.roads)
    size = (work / "cr" / "scenario.xml").stat().st_size
    print(f"{path}: {len(sc.actors)} actors, {len(cr.dynamic_obstacles)} dynamic obstacles, "
          f"{states} states, {len(cr.lanelet_network.lanelets)} lanelets for {lanes} lanes, "
          f"largest position error {worst * 1000:.2f} mm, export {cpu:.2f} s CPU, "
          f"{size / 1000:.0f} kB")


def main() -> None:
    for path in sys.argv[1:]:
        with tempfile.TemporaryDirectory() as tmp:
            report(path, Path(tmp))


if __name__ == "__main__":
    main()
