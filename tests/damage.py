"""Damaged copies of valid input files, for the readers' property tests.

A reader given arbitrary bytes, or a valid file with a few bytes or numbers damaged, must
return a result or raise the project's :class:`~vid2sim.base.errors.InputError`, and nothing else
(no ValueError, OverflowError, RecursionError, UnicodeDecodeError... reaching the user as an
"internal error").
"""

from __future__ import annotations

import os
import re

from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

from vid2sim.base.errors import InputError

#: Examples per damage property test; ``VID2SIM_FUZZ_EXAMPLES=1000`` for a deeper local run.
FUZZ = settings(max_examples=int(os.environ.get("VID2SIM_FUZZ_EXAMPLES", "60")), deadline=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture])

#: What a damaged or hostile file puts where a number belongs.
NUMBER_JUNK = ("nan", "NaN", "inf", "-inf", "1e400", "-1e400", "1e300", "-1e300", "1e-320",
               "0", "-0", "-1", "1e9", "99999999999999999999999999", "", "x", "1,5", "0x1F",
               "true", "null", "[]", "{}", '"7"', ".", "-", "1e", "١٢")

_NUMBER = re.compile(rb"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")


@st.composite
def byte_damage(draw, valid: bytes) -> bytes:
    """``valid`` with 1-4 random edits: a byte flipped, set, inserted or deleted, a chunk
    duplicated, or the end cut off."""
    data = bytearray(valid)
    for _ in range(draw(st.integers(1, 4))):
        kind = draw(st.sampled_from(["flip", "set", "insert", "delete", "duplicate", "truncate"]))
        pos = draw(st.integers(0, max(len(data) - 1, 0)))
        if kind == "flip" and data:
            data[pos] ^= 1 << draw(st.integers(0, 7))
        elif kind == "set" and data:
            data[pos] = draw(st.integers(0, 255))
        elif kind == "insert":
            data[pos:pos] = draw(st.binary(min_size=1, max_size=8))
        elif kind == "delete":
            del data[pos:pos + draw(st.integers(1, 16))]
        elif kind == "duplicate":
            data[pos:pos] = data[pos:pos + draw(st.integers(1, 64))]
        elif kind == "truncate":
            del data[pos:]
    return bytes(data)


@st.composite
def number_damage(draw, valid: bytes) -> bytes:
    """``valid`` with 1-3 of its numbers replaced by junk (:data:`NUMBER_JUNK`)."""
    spans = [m.span() for m in _NUMBER.finditer(valid)]
    data = valid
    for _ in range(draw(st.integers(1, 3))):
        if not spans:
            break
        a, b = draw(st.sampled_from(spans))
        junk = draw(st.sampled_from(NUMBER_JUNK)).encode()
        data = data[:a] + junk + data[b:]
        spans = [m.span() for m in _NUMBER.finditer(data)]
    return data


def damaged(valid: bytes) -> st.SearchStrategy[bytes]:
    """Arbitrary bytes, or ``valid`` with bytes or numbers damaged."""
    return st.one_of(st.binary(max_size=512), byte_damage(valid), number_damage(valid))


def input_error_or_result(fn, *args, **kwargs):
    """Call ``fn``; an :class:`InputError` is an allowed outcome (returned, not raised), any
    other exception fails the test."""
    try:
        return fn(*args, **kwargs)
    except InputError as exc:
        return exc
