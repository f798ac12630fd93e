"""The OpenStreetMap reader (vid2sim.geo.osm, used read-only) on arbitrary and damaged bytes:
a road network or the project's InputError, nothing else."""

from __future__ import annotations

import math

import pytest
from hypothesis import given

from tests.damage import FUZZ, damaged, input_error_or_result
from vid2sim.base.errors import ImpossibleValueError
from vid2sim.core.records import Origin
from vid2sim.geo.osm import load_network

ORIGIN = Origin(60.17, 24.94, 0.0)


def _small_map() -> bytes:
    nodes = "".join(f'  <node id="{i}" version="1" lat="{60.17 + 1e-4 * i:.7f}" lon="24.94"/>\n'
                    for i in range(1, 6))
    way = ('  <way id="100" version="1">\n'
           + "".join(f'    <nd ref="{i}"/>\n' for i in range(1, 6))
           + '    <tag k="highway" v="primary"/>\n    <tag k="lanes" v="2"/>\n  </way>\n')
    return ('<?xml version="1.0" encoding="UTF-8"?>\n<osm version="0.6" generator="test">\n'
            + nodes + way + "</osm>\n").encode()


@pytest.mark.parametrize("name", ["map.osm", "map.osm.pbf"])
def test_osm_damage_gives_input_error_only(tmp_path, name):
    @FUZZ
    @given(data=damaged(_small_map()))
    def check(data):
        path = tmp_path / name
        path.write_bytes(data)
        net = input_error_or_result(load_network, path, ORIGIN)
        if hasattr(net, "bbox_lonlat"):  # a network that loads lies on the earth
            assert all(math.isfinite(v) for v in net.bbox_lonlat)

    check()


@pytest.mark.parametrize("field", ["way", "node"])
def test_an_id_beyond_64_bits_is_an_input_error(tmp_path, field):
    """Found by the damage test above: a way id of 26 digits overflowed numpy's int64."""
    big = "9" * 26
    data = _small_map().decode()
    data = (data.replace('<way id="100"', f'<way id="{big}"') if field == "way"
            else data.replace('node id="1"', f'node id="{big}"').replace('ref="1"',
                                                                      f'ref="{big}"'))
    path = tmp_path / "map.osm"
    path.write_text(data)
    with pytest.raises(ImpossibleValueError):  # an id beyond 64 bits
        load_network(path, ORIGIN)
