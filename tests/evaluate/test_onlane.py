"""Where replayed vehicles stand on the gym network: a generated street whose vehicles stand
where a street puts them is all on its lanes; the same street as one default lane is not."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from vid2sim.evaluate.onlane import lane_occupancy
from vid2sim.samples.scenarios import street_scenario


def test_street_vehicles_are_all_on_their_lanes():
    occ = lane_occupancy(street_scenario())
    assert occ.steps > 0
    assert occ.share == 1.0 and occ.road_share == 1.0
    assert occ.by_type["parking"] == occ.by_group["static"][0]
    assert occ.by_type["rail"] == occ.by_group["rail"][0]
    assert occ.by_group["moving"][1] == occ.by_group["moving"][0]


def test_a_single_default_lane_leaves_the_street_off_the_road():
    sc = street_scenario()
    road = replace(sc.roads[0], lanes=1, cross_section=None)
    occ = lane_occupancy(replace(sc, roads=[road]))
    # only the ego's lane is left (centred on the road line, 3.25 m wide): parked cars, the
    # tram and the oncoming car stand beside it
    assert occ.share < 0.5
    assert np.isfinite(occ.road_share)
