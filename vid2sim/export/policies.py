"""Moved to :mod:`vid2sim.adas.policies` (this name keeps old imports working)."""

from vid2sim.adas.policies import (  # noqa: F401
    DEFAULT_ACCEL_RANGE_MPS2,
    AccPolicy,
    AebPolicy,
    FollowLogPolicy,
    Policy,
    accel_to_action,
    run_episode,
)
