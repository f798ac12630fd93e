"""Export: scenario assembly, the highway-env gymnasium environment, OpenSCENARIO/OpenDRIVE."""

from __future__ import annotations

from pathlib import Path

FORMATS = ("highway-env", "openscenario")

_REPLAY_SCRIPT = '''"""Replay {name} in highway-env (written by `vid2sim export --format highway-env`).

    python replay.py            # ACC + AEB of vid2sim.adas through the camera model
    python replay.py --log      # ego on its logged trajectory (what the evaluator does)

The actors replay their logs; `vid2sim test-policy` runs the same with variations and reports.
"""
import sys
from pathlib import Path

import gymnasium

import vid2sim  # noqa: F401  registers vid2sim/Replay-v0
from vid2sim import scenario as scenario_io
from vid2sim.adas.metrics import episode_metrics
from vid2sim.adas.registry import parse_policy
from vid2sim.adas.sensor import CameraSensor

here = Path(__file__).resolve().parent
scenario = scenario_io.load(here / "scenario.json")
spec = parse_policy("log" if "--log" in sys.argv else "acc+aeb")
env = CameraSensor(gymnasium.make("vid2sim/Replay-v0", scenario=scenario, ego_mode=spec.ego_mode))
policy = spec.make(scenario, env.unwrapped.config)
obs, info = env.reset(seed=0)
infos = [info]
done = False
while not done:
    obs, reward, terminated, truncated, info = env.step(policy(obs, info))
    infos.append(info)
    done = terminated or truncated
m = episode_metrics(infos, 1.0 / env.unwrapped.config["policy_frequency"], scenario.ego.width_m)
print(f"{{len(infos) - 1}} steps, {{infos[-1]['t_s']:.1f}} s simulated, "
      f"collision={{m.collision}}, min TTC {{m.min_ttc_s:.2f}} s, min gap {{m.min_gap_m:.1f}} m")
'''


def run_export(scenario_path: Path, fmt: str, out_dir: Path) -> str:
    """Export a scenario.json; returns a summary for the CLI.

    ``openscenario``: ``out_dir/scenario.xosc`` + ``out_dir/road.xodr``.
    ``highway-env``: ``out_dir/scenario.json`` (canonical copy), ``out_dir/replay.py`` (runnable
    example: the ACC + AEB of :mod:`vid2sim.adas` through its camera model, or ``--log``) and
    ``out_dir/preview.png`` (top view of the replay
    with the logged ego at mid-scenario).
    """
    from vid2sim import scenario as scenario_io
    from vid2sim.errors import InputError
    from vid2sim.fileio import write_bytes_atomic, write_text_atomic

    sc = scenario_io.load(scenario_path)
    out_dir = Path(out_dir)
    if fmt == "openscenario":
        from vid2sim.export.openscenario import write_openscenario

        xosc_path, xodr_path = write_openscenario(sc, out_dir)
        return (f"wrote {xosc_path} (OpenSCENARIO 1.2, {1 + len(sc.actors)} vehicles, "
                f"{sc.duration_s:.1f} s) and {xodr_path} (OpenDRIVE 1.8, "
                f"{max(len(sc.roads), 1)} road(s))")
    if fmt != "highway-env":
        raise InputError(None, f"unknown export format {fmt!r}", f"use one of {', '.join(FORMATS)}")
    import cv2
    import numpy as np

    from vid2sim.export.highway import ReplayEnv

    scenario_io.save(sc, out_dir / "scenario.json")
    v_ref = max(float(np.max(sc.ego.trajectory.speed)), 5.0)
    write_text_atomic(out_dir / "replay.py",
                      _REPLAY_SCRIPT.format(name=Path(scenario_path).name, v_ref=v_ref))
    env = ReplayEnv(sc, ego_mode="log", render_mode="rgb_array",
                    config={"screen_width": 800, "screen_height": 400})
    env.reset(seed=0)
    action = np.zeros(1, dtype=np.float32)
    for _ in range(env.n_steps // 2):
        env.step(action)
    frame = env.render()
    env.close()
    ok, png = cv2.imencode(".png", cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
    if not ok:  # pragma: no cover - PNG encoding of an RGB array does not fail
        raise RuntimeError("PNG encoding failed")
    write_bytes_atomic(out_dir / "preview.png", png.tobytes())
    return (f"wrote {out_dir / 'scenario.json'}, {out_dir / 'replay.py'} and "
            f"{out_dir / 'preview.png'} ({1 + len(sc.actors)} vehicles, {sc.duration_s:.1f} s; "
            f"run: python {out_dir / 'replay.py'})")
