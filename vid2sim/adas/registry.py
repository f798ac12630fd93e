"""Which policy ``--policy`` names: a built-in driving function or the user's own.

Built-ins (:func:`parse_policy`): ``log`` (the recorded ego, replayed as logged), and any
``+``-combination of ``acc`` (adaptive cruise), ``aeb`` (emergency braking) and ``lka`` (lane
keeping): ``acc``, ``aeb``, ``acc+aeb``, ``lka``, ``acc+lka``, ``acc+aeb+lka``. Without
``acc`` the longitudinal control is the recorded driver's speed profile (so ``aeb`` is the
recorded driver with AEB, ``lka`` the recorded speeds with lane keeping). ``lka`` gives the
environment lateral control.

User policies: ``module:NAME`` or ``path/to/file.py:NAME`` (the current folder is on the
import path). ``NAME`` may be

- a function ``policy(observation, info) -> action``;
- an object with ``predict(observation)`` (a Stable-Baselines3-style agent: called with
  ``deterministic=True`` when it accepts it; a returned ``(action, state)`` tuple is unpacked)
  or ``act(observation)`` (checked in that order, before ``__call__``);
- a class: instantiated without arguments for every episode, then used as above.

An object's ``reset()``, if any, is called before every episode. It receives the camera
observation of :mod:`vid2sim.adas.sensor` unless it has ``observation = "kinematics"`` (the
environment's own Kinematics array), and the environment's ``info``. The action is
``Box(-1, 1, (1,))`` (acceleration), or ``(2,)`` (acceleration, steering) when it has
``lateral = True``.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vid2sim.adas.functions import (
    MIN_SET_SPEED_MPS,
    AdaptiveCruise,
    DrivingFunction,
    EmergencyBraking,
    LaneKeeping,
    RecordedDriver,
)
from vid2sim.base.errors import FormatError, InconsistentInputError, InputError, MissingInputError
from vid2sim.core.scenario import Scenario

BUILT_INS = ("log", "acc", "aeb", "lka")
_HINT = ("use log, acc, aeb, lka or a +-combination such as acc+aeb, or module:callable "
         "for your own")


@dataclass(frozen=True)
class PolicySpec:
    """A resolved ``--policy``: how to run it and how to make one instance per episode."""

    name: str
    ego_mode: str = "policy"
    """``log`` replays the recorded ego; ``policy`` lets the policy drive."""
    lateral: bool = False
    """The policy steers (the environment's lateral control)."""
    observation: str = "camera"
    """``camera`` (:mod:`vid2sim.adas.sensor`) or ``kinematics`` (the environment's own)."""
    components: tuple[str, ...] = ()
    target: object = None  # a user's function, object or class

    def make(self, scenario: Scenario, env_config: dict) -> Callable:
        """A fresh policy for one episode on ``scenario``."""
        if self.ego_mode == "log":
            return lambda obs, info: np.zeros(1, dtype=np.float32)
        if self.target is not None:
            return _user_policy(self.target)
        return built_in_function(self.components, scenario, env_config)


def built_in_function(components: tuple[str, ...], scenario: Scenario,
                      env_config: dict) -> DrivingFunction:
    """The :class:`DrivingFunction` of a set of built-in components on a scenario."""
    ego_log = scenario.ego.trajectory
    if "acc" in components:
        # the set speed: the recorded driver's top speed (not below ACC's lowest setting)
        set_speed = max(float(np.max(ego_log.speed)), MIN_SET_SPEED_MPS)
        longitudinal = AdaptiveCruise(set_speed_mps=set_speed)
    else:
        longitudinal = RecordedDriver(ego_log)
    accel_range = tuple(env_config.get("acceleration_range_mps2", (-8.0, 8.0)))
    aeb = None
    if "aeb" in components:
        aeb = EmergencyBraking(full_decel_mps2=-float(accel_range[0]))
    lka = LaneKeeping(length_m=scenario.ego.length_m) if "lka" in components else None
    fn = DrivingFunction(longitudinal, aeb, lka, accel_range_mps2=accel_range)
    if "steering_range_rad" in env_config:
        fn.steering_range_rad = tuple(env_config["steering_range_rad"])
    return fn


def parse_policy(text: str) -> PolicySpec:
    """Resolve ``--policy``; raises :class:`InputError` for an unknown name or a user policy
    that does not import or cannot act."""
    text = (text or "").strip()
    if not text:
        raise FormatError(None, "--policy is empty", _HINT)
    if ":" in text:
        return _parse_user(text)
    parts = tuple(p.strip() for p in text.lower().split("+"))
    unknown = [p for p in parts if p not in BUILT_INS]
    if unknown or not parts:
        raise FormatError(None, f"unknown policy {text!r}", _HINT)
    if "log" in parts:
        if len(parts) > 1:
            raise InconsistentInputError(
                None, f"policy {text!r}: log replays the recording and combines "
                "with nothing", _HINT)
        return PolicySpec("log", ego_mode="log")
    if len(set(parts)) != len(parts):
        raise FormatError(None, f"policy {text!r} names a function twice", _HINT)
    order = tuple(p for p in ("acc", "aeb", "lka") if p in parts)
    return PolicySpec("+".join(order), lateral="lka" in parts, components=order)


def _parse_user(text: str) -> PolicySpec:
    module_name, _, attr = text.rpartition(":")
    if not module_name or not attr:
        raise FormatError(None, f"policy {text!r}: expected module:callable", _HINT)
    target = getattr(_import(module_name, text), attr, None) if attr.isidentifier() else None
    if target is None:
        raise MissingInputError(None, f"policy {text!r}: {module_name} has no {attr!r}",
                                "check the name after the colon")
    if inspect.isclass(target):  # instantiated per episode: can its instances act?
        acts = (any(callable(getattr(target, m, None)) for m in ("predict", "act"))
                or any("__call__" in vars(k) for k in target.__mro__ if k is not object))
    else:
        acts = callable(target) or any(callable(getattr(target, m, None))
                                       for m in ("predict", "act"))
    if not acts:
        raise FormatError(None, f"policy {text!r} is not callable",
                          "give a function (observation, info) -> action or an agent with "
                          "predict(observation) or act(observation)")
    observation = getattr(target, "observation", "camera")
    if observation not in ("camera", "kinematics"):
        raise FormatError(None, f"policy {text!r}: observation must be 'camera' or "
                          f"'kinematics', not {observation!r}")
    return PolicySpec(text, lateral=bool(getattr(target, "lateral", False)),
                      observation=observation, target=target)


def _import(module_name: str, text: str):
    try:
        if module_name.endswith(".py") or os.sep in module_name or "/" in module_name:
            path = Path(module_name)
            if not path.is_file():
                raise MissingInputError(path, "no such policy file", "give module:callable or "
                                        "path/to/file.py:callable")
            spec = importlib.util.spec_from_file_location(f"vid2sim_user_{path.stem}", path)
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
            return module
        if os.getcwd() not in sys.path:
            sys.path.insert(0, os.getcwd())  # a policy beside the user, as `python -m` finds it
        return importlib.import_module(module_name)
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - any failure of the user's module is bad input
        raise InputError(None, f"policy {text!r}: module {module_name!r} does not import "
                         f"({type(exc).__name__}: {exc})",
                         "check that it is on the import path and runs") from None


def _user_policy(target) -> Callable:
    """A callable ``(obs, info) -> action`` for a user's function, agent or class."""
    agent = target() if inspect.isclass(target) else target
    reset = getattr(agent, "reset", None)
    if callable(reset) and not inspect.isfunction(agent):
        reset()
    predict = getattr(agent, "predict", None)
    if callable(predict):
        takes_flag = "deterministic" in _parameters(predict)

        def call(obs, info):
            out = predict(obs, deterministic=True) if takes_flag else predict(obs)
            return _action(out[0] if isinstance(out, tuple) else out)
        return call
    act = getattr(agent, "act", None)
    if callable(act):
        return lambda obs, info: _action(act(obs))
    return lambda obs, info: _action(agent(obs, info))


def _parameters(fn) -> set[str]:
    try:
        return set(inspect.signature(fn).parameters)
    except (TypeError, ValueError):
        return set()


def _action(value) -> np.ndarray:
    return np.asarray(value, dtype=np.float32).reshape(-1)


def describe(spec: PolicySpec) -> str:
    """One phrase for reports: what drives the ego."""
    if spec.ego_mode == "log":
        return "log (the recorded ego, replayed)"
    if spec.target is not None:
        return f"{spec.name} (user policy, {spec.observation} observation)"
    words = {"acc": "ACC", "aeb": "AEB", "lka": "LKA"}
    base = "" if "acc" in spec.components else "recorded driver + "
    return base + " + ".join(words[c] for c in spec.components)

