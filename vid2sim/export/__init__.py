"""Export: scenario assembly, the highway-env gymnasium environment, OpenSCENARIO/OpenDRIVE,
CommonRoad.

The ``vid2sim export`` command itself (loading, staging the outputs) is
:func:`vid2sim.app.commands.run_export`.
"""

from __future__ import annotations

FORMATS = ("highway-env", "openscenario", "commonroad")

_REPLAY_SCRIPT = '''"""Replay {name} in highway-env (written by `vid2sim export --format highway-env`).

    python replay.py            # ACC + AEB of vid2sim.adas through the camera model
    python replay.py --log      # ego on its logged trajectory (what the evaluator does)

The actors replay their logs; `vid2sim test-policy` runs the same with variations and reports.
"""
import sys
from pathlib import Path

import gymnasium

import vid2sim  # noqa: F401  registers vid2sim/Replay-v0
from vid2sim.core import scenario as scenario_io
from vid2sim.adas.episode_metrics import episode_metrics
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


def replay_script(scenario_name: str, v_ref_mps: float) -> str:
    """The runnable ``replay.py`` of a highway-env export: the scenario file beside it, the
    ACC + AEB of :mod:`vid2sim.adas` through its camera model at ``v_ref_mps`` desired speed,
    or ``--log``."""
    return _REPLAY_SCRIPT.format(name=scenario_name, v_ref=v_ref_mps)
