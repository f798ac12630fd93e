"""--policy: built-in names, combinations, and users' functions, agents and classes."""

from __future__ import annotations

import re

import numpy as np
import pytest

from vid2sim.adas.episode import run_episode
from vid2sim.adas.functions import AdaptiveCruise, DrivingFunction, RecordedDriver
from vid2sim.adas.registry import parse_policy
from vid2sim.base.errors import (
    FormatError,
    ImpossibleValueError,
    InconsistentInputError,
    InputError,
    MissingInputError,
)
from vid2sim.samples.scenarios import straight_scenario

USER = '''
import numpy as np

observed = []


def brake_gently(observation, info):
    observed.append(np.asarray(observation).shape)
    return [-0.125]  # -1 m/s^2


class Agent:
    """Stable-Baselines3 style: predict(obs, deterministic) -> (action, state)."""

    def __init__(self):
        self.resets = 0

    def reset(self):
        self.resets += 1

    def predict(self, observation, deterministic=False):
        return np.array([0.0], np.float32), None


class Actor:
    observation = "kinematics"

    def act(self, observation):
        assert observation.shape == (8, 7)  # the environment's own Kinematics array
        return np.array([0.0])


class Steering:
    lateral = True

    def __call__(self, observation, info):
        return [0.0, 0.0]


agent = Agent()
not_a_policy = 42
'''


@pytest.fixture()
def user_module(tmp_path, monkeypatch):
    (tmp_path / "my_policies.py").write_text(USER)
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path
    import sys

    sys.modules.pop("my_policies", None)


def test_built_in_names_and_combinations():
    assert parse_policy("log").ego_mode == "log"
    assert parse_policy("acc").components == ("acc",)
    spec = parse_policy("AEB+acc")
    assert spec.components == ("acc", "aeb") and spec.name == "acc+aeb" and not spec.lateral
    assert parse_policy("lka").lateral
    fn = parse_policy("aeb").make(straight_scenario(), {})
    assert isinstance(fn, DrivingFunction) and isinstance(fn.longitudinal, RecordedDriver)
    assert fn.aeb is not None and fn.lka is None
    acc = parse_policy("acc").make(straight_scenario(), {}).longitudinal
    assert isinstance(acc, AdaptiveCruise) and acc.set_speed_mps == pytest.approx(10.0)


@pytest.mark.parametrize("text, error", [
    ("", FormatError), ("ac", FormatError), ("acc+acc", FormatError), ("acc+", FormatError),
    ("cruise", FormatError),
    ("log+aeb", InconsistentInputError),  # the recording's driver combines with nothing
])
def test_unknown_built_ins_are_input_errors(text, error):
    with pytest.raises(error):
        parse_policy(text)


def test_user_function_gets_the_camera_observation(user_module):
    spec = parse_policy("my_policies:brake_gently")
    assert spec.observation == "camera" and not spec.lateral
    r = run_episode(straight_scenario(duration_s=3.0), spec)
    import my_policies

    assert my_policies.observed[0] == (10, 6)
    assert r.metrics.max_decel_mps2 == pytest.approx(1.0, abs=1e-6)


def test_user_agents_and_classes(user_module):
    sc = straight_scenario(duration_s=3.0)
    import my_policies

    run_episode(sc, parse_policy("my_policies:agent"))
    run_episode(sc, parse_policy("my_policies:agent"))
    assert my_policies.agent.resets == 2  # reset() before every episode
    assert parse_policy("my_policies:Actor").observation == "kinematics"
    run_episode(sc, parse_policy("my_policies:Actor"))
    steering = parse_policy("my_policies:Steering")
    assert steering.lateral
    assert not run_episode(sc, steering).metrics.collision


def test_user_policy_from_a_file_path(tmp_path):
    path = tmp_path / "pol.py"
    path.write_text("def go(o, i):\n    return [0.0]\n")
    spec = parse_policy(f"{path}:go")
    assert spec.make(straight_scenario(), {})(np.zeros((10, 6)), {}).tolist() == [0.0]


@pytest.mark.parametrize("text,error", [
    # a module that does not import: no named class says why (syntax, a missing dependency...)
    ("no_such_module_xyz:policy", InputError),
    ("my_policies:missing", MissingInputError),
    ("my_policies:not_a_policy", FormatError),  # not callable
    ("my_policies:", FormatError),  # not module:callable
    ("/no/such/file.py:go", MissingInputError),
])
def test_bad_user_policies_are_input_errors(user_module, text, error):
    with pytest.raises(error, match=re.escape(text.rpartition(":")[0])):  # names the module
        parse_policy(text)


def test_a_module_that_raises_on_import_is_an_input_error(tmp_path, monkeypatch):
    (tmp_path / "broken_pol.py").write_text("raise RuntimeError('boom')\n")
    monkeypatch.chdir(tmp_path)
    with pytest.raises(InputError, match="boom"):  # the module's own error, for its author
        parse_policy("broken_pol:policy")


def test_a_policy_returning_the_wrong_action_is_an_input_error(tmp_path):
    path = tmp_path / "wrong.py"
    path.write_text("def two(o, i):\n    return [0.0, 0.0]\n"
                    "def nan(o, i):\n    return [float('nan')]\n"
                    "def boom(o, i):\n    raise ValueError('oops')\n")
    for name, error, datum in (("two", ImpossibleValueError, r"\[0\.0, 0\.0\]"),
                               ("nan", ImpossibleValueError, "nan"),
                               ("boom", InputError, "oops")):  # the policy's own error
        with pytest.raises(error, match=datum):
            run_episode(straight_scenario(duration_s=3.0), parse_policy(f"{path}:{name}"))
