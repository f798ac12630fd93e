"""The batch manifest reader on arbitrary and damaged bytes: rows or the project's InputError,
nothing else; every row gets the same input checks as a single build."""

from __future__ import annotations

import pytest
from hypothesis import given

from tests.damage import FUZZ, damaged, input_error_or_result
from vid2sim.app.batch import read_manifest
from vid2sim.base.errors import InputError


def _folder(tmp_path):
    for name in ("a.mp4", "b.mp4", "a.gpx", "cam.yaml"):
        (tmp_path / name).write_text("x")
    return tmp_path


def test_manifest_damage_gives_input_error_only(tmp_path):
    folder = _folder(tmp_path)
    valid = (b"video,name,gps,camera,fps,gps_offset_s,ego_speed_mps\n"
             b"a.mp4,one,a.gpx,cam.yaml,10,0.5,\nb.mp4,two,,,25,,3.0\n")

    @FUZZ
    @given(data=damaged(valid))
    def check(data):
        manifest = folder / "manifest.csv"
        manifest.write_bytes(data)
        input_error_or_result(read_manifest, manifest)

    check()


@pytest.mark.parametrize("cells,match", [
    ("a.mp4,,nan,", "fps"), ("a.mp4,,10,1e300", "offset"), ("a.mp4,,10,,1e9", "speed"),
    ("a.mp4,,inf,", "fps"),
])
def test_manifest_numbers_get_the_single_build_checks(tmp_path, cells, match):
    folder = _folder(tmp_path)
    manifest = folder / "m.csv"
    manifest.write_text(f"video,name,fps,gps_offset_s,ego_speed_mps\n{cells}\n")
    with pytest.raises(InputError, match=match):
        read_manifest(manifest)
