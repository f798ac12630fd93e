"""WGS-84 <-> ECEF <-> ENU: known values, axis conventions, round trips below 1 mm at 10 km."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vid2sim.core.enu import EnuFrame, ecef_to_geodetic, geodetic_to_ecef
from vid2sim.core.records import Origin

A_M = 6378137.0  # WGS-84 semi-major axis (definition)
B_M = 6356752.314245  # WGS-84 semi-minor axis (published derived constant)
F = 1 / 298.257223563
E2 = F * (2 - F)


def ecef_closed_form(lat_deg: float, lon_deg: float, h_m: float) -> np.ndarray:
    """The textbook geodetic -> ECEF formula, independent of pyproj."""
    la, lo = math.radians(lat_deg), math.radians(lon_deg)
    n = A_M / math.sqrt(1 - E2 * math.sin(la) ** 2)
    return np.array([(n + h_m) * math.cos(la) * math.cos(lo),
                     (n + h_m) * math.cos(la) * math.sin(lo),
                     (n * (1 - E2) + h_m) * math.sin(la)])


@pytest.mark.parametrize("lat,lon,h,expect", [
    (0.0, 0.0, 0.0, (A_M, 0.0, 0.0)),  # equator / prime meridian
    (0.0, 90.0, 0.0, (0.0, A_M, 0.0)),
    (0.0, 180.0, 100.0, (-(A_M + 100.0), 0.0, 0.0)),
    (90.0, 0.0, 0.0, (0.0, 0.0, B_M)),  # north pole at the semi-minor axis
    (-90.0, 0.0, 10.0, (0.0, 0.0, -(B_M + 10.0))),
])
def test_ecef_known_values(lat, lon, h, expect):
    assert geodetic_to_ecef(lat, lon, h)[0] == pytest.approx(expect, abs=1e-3)


@pytest.mark.parametrize("lat,lon,h", [
    (60.1699, 24.9384, 20.0),  # Helsinki
    (49.015003823272, 8.4342971002335, 116.43),  # KITTI drive 0001 start
    (-33.8688, 151.2093, 50.0),
    (37.7749, -122.4194, -30.0),
])
def test_ecef_against_closed_form_and_back(lat, lon, h):
    ecef = geodetic_to_ecef(lat, lon, h)[0]
    assert ecef == pytest.approx(ecef_closed_form(lat, lon, h), abs=1e-4)
    la, lo, hh = ecef_to_geodetic(ecef)
    assert la[0] == pytest.approx(lat, abs=1e-10)
    assert lo[0] == pytest.approx(lon, abs=1e-10)
    assert hh[0] == pytest.approx(h, abs=1e-4)


def test_enu_axes_and_scale():
    o = Origin(60.0, 25.0, 0.0)
    frame = EnuFrame(o)
    assert frame.to_enu(o.lat, o.lon, o.alt)[0] == pytest.approx((0, 0, 0), abs=1e-6)
    # 0.001 deg north ~ M * dphi, M the meridian radius of curvature.
    m = A_M * (1 - E2) / (1 - E2 * math.sin(math.radians(60)) ** 2) ** 1.5
    north = frame.to_enu(60.001, 25.0, 0.0)[0]
    assert north[1] == pytest.approx(m * math.radians(0.001), rel=1e-6)
    assert abs(north[0]) < 1e-6
    n_prime = A_M / math.sqrt(1 - E2 * math.sin(math.radians(60)) ** 2)
    east = frame.to_enu(60.0, 25.001, 0.0)[0]
    assert east[0] == pytest.approx(n_prime * math.cos(math.radians(60)) * math.radians(0.001),
                                    rel=1e-6)
    assert frame.to_enu(60.0, 25.0, 5.0)[0] == pytest.approx((0, 0, 5.0), abs=1e-6)


def test_enu_round_trip_below_1mm_at_10km():
    frame = EnuFrame(Origin(60.1699, 24.9384, 20.0))
    ang = np.linspace(0, 2 * np.pi, 37)
    pts = np.column_stack((1e4 * np.cos(ang), 1e4 * np.sin(ang), np.full(len(ang), 3.0)))
    lat, lon, alt = frame.to_geodetic(pts)
    back = frame.to_enu(lat, lon, alt)
    assert np.max(np.linalg.norm(back - pts, axis=1)) < 1e-3


def test_to_geodetic_accepts_two_columns():
    frame = EnuFrame(Origin(10.0, 20.0, 0.0))
    lat, lon, _ = frame.to_geodetic(np.array([[100.0, 200.0]]))
    assert frame.to_enu(lat, lon, 0.0)[0, :2] == pytest.approx((100.0, 200.0), abs=0.01)


@settings(max_examples=60, deadline=None)
@given(lat=st.floats(-80, 80), lon=st.floats(-180, 180), alt=st.floats(-100, 3000),
       e=st.floats(-1e4, 1e4), n=st.floats(-1e4, 1e4), u=st.floats(-50, 50))
def test_enu_round_trip_property(lat, lon, alt, e, n, u):
    frame = EnuFrame(Origin(lat, lon, alt))
    la, lo, h = frame.to_geodetic(np.array([[e, n, u]]))
    back = frame.to_enu(la, lo, h)[0]
    assert np.linalg.norm(back - (e, n, u)) < 1e-3


def test_proj_string_names_origin():
    s = EnuFrame(Origin(60.1699, 24.9384, 20.0)).proj_string()
    assert "+proj=topocentric" in s and "+lat_0=60.169900000" in s and "+lon_0=24.938400000" in s
