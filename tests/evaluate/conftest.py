"""Scenarios built in code for the evaluation tests (no files, no real data)."""

from __future__ import annotations

import pytest

from vid2sim.samples.scenarios import KITTI_LIKE_CAMERA as CAMERA
from vid2sim.samples.scenarios import parallel_traffic_scenario as make_scenario

__all__ = ["CAMERA", "make_scenario"]
from vid2sim.core.scenario import Scenario


@pytest.fixture
def scenario() -> Scenario:
    return make_scenario()
