"""Export: scenario assembly, the highway-env gymnasium environment, OpenSCENARIO/OpenDRIVE.

The ``vid2sim export`` command itself (loading, staging the outputs) is
:func:`vid2sim.app.commands.run_export`.
"""

from __future__ import annotations

FORMATS = ("highway-env", "openscenario")

_REPLAY_SCRIPT = '''"""Replay {name} in highway-env (written by `vid2sim export --format highway-env`).

    python replay.py            # ACC (IDM) ego with AEB, actors replay their logs
    python replay.py --log      # ego on its logged trajectory (what the evaluator does)
"""
import sys
from pathlib import Path

import gymnasium

import vid2sim  # noqa: F401  registers vid2sim/Replay-v0
from vid2sim.export.policies import AccPolicy, AebPolicy, run_episode

here = Path(__file__).resolve().parent
env = gymnasium.make("vid2sim/Replay-v0", scenario=here / "scenario.json")
log_mode = "--log" in sys.argv
policy = AebPolicy(base=AccPolicy(desired_speed_mps={v_ref:.1f}))
infos = run_episode(env, policy, seed=0, options={{"ego_mode": "log" if log_mode else "policy"}})
ttc = min(i["ttc_s"] for i in infos)
gaps = [i["gap_m"] for i in infos if i["lead_id"] is not None]
print(f"{{len(infos) - 1}} steps, {{infos[-1]['t_s']:.1f}} s simulated, "
      f"crashed={{any(i['crashed'] for i in infos)}}, min TTC {{ttc:.2f}} s, "
      f"min gap {{min(gaps) if gaps else float('nan'):.1f}} m")
'''


def replay_script(scenario_name: str, v_ref_mps: float) -> str:
    """The runnable ``replay.py`` of a highway-env export: the scenario file beside it,
    an ACC (IDM) ego with AEB at ``v_ref_mps`` desired speed, or ``--log``."""
    return _REPLAY_SCRIPT.format(name=scenario_name, v_ref=v_ref_mps)
