"""Criticality measures of commonroad-crime on an exported CommonRoad scenario.

Runs in the venv .ci/commonroad_crime.sh makes (commonroad-crime pins commonroad-io 2024.3,
protobuf 3.20.2 and opencv-python 4, which vid2sim's own environment excludes), never in the
project's. Reads scenario.xml with CommonRoadFileReader (lanelet assignment on) and the
ids.json written beside it by ``vid2sim export --format commonroad --ego-as-obstacle``, and
writes JSON: for every other obstacle and every time step where both it and the ego exist,
commonroad-crime's TTC, THW and HW (headway distance) of the ego to it.

usage: python crime_measures.py SCENARIO_XML IDS_JSON OUT_JSON
"""

from __future__ import annotations

import json
import logging
import math
import sys
import warnings


def _number(value):
    value = float(value)
    if math.isnan(value):
        return None
    if math.isinf(value):
        return "inf" if value > 0 else "-inf"
    return value


def main(xml_path: str, ids_path: str, out_path: str) -> int:
    warnings.filterwarnings("ignore")
    logging.disable(logging.WARNING)
    from commonroad.common.file_reader import CommonRoadFileReader
    from commonroad_crime.data_structure.configuration import CriMeConfiguration
    from commonroad_crime.measure import HW, THW, TTC

    with open(ids_path, encoding="utf-8") as f:
        ids = json.load(f)
    ego_id = ids["ego"]
    if ego_id is None:
        print("crime_measures: export with --ego-as-obstacle", file=sys.stderr)
        return 2
    scenario, _ = CommonRoadFileReader(xml_path).open(lanelet_assignment=True)
    config = CriMeConfiguration()
    config.update(ego_id=ego_id, sce=scenario)
    measures = {"ttc_s": TTC(config), "thw_s": THW(config), "hw_m": HW(config)}
    ego = scenario.obstacle_by_id(ego_id)
    steps = range(ego.initial_state.time_step, ego.prediction.final_time_step + 1)
    actors = {v: k for k, v in ids["actors"].items()}
    rows = []
    for obstacle in scenario.dynamic_obstacles:
        if obstacle.obstacle_id == ego_id:
            continue
        for k in steps:
            if obstacle.state_at_time(k) is None:
                continue
            row = {"actor": actors.get(obstacle.obstacle_id, str(obstacle.obstacle_id)),
                   "time_step": k}
            for name, measure in measures.items():
                try:
                    row[name] = _number(measure.compute(obstacle.obstacle_id, k, verbose=False))
                except Exception as exc:  # noqa: BLE001 - a measure undefined at this step
                    row[name] = None
                    row.setdefault("errors", []).append(f"{name}: {type(exc).__name__}")
                measure.other_vehicle = None  # re-read the obstacle each time
            rows.append(row)
    import commonroad_crime

    out = {"tool": f"commonroad-crime {getattr(commonroad_crime, '__version__', '?')}",
           "dt_s": scenario.dt, "ego": ego_id, "rows": rows}
    with open(out_path, "w", encoding="utf-8") as f:
        json.dump(out, f, indent=1)
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 4:
        print(__doc__.strip().splitlines()[-1], file=sys.stderr)
        sys.exit(2)
    sys.exit(main(*sys.argv[1:]))
