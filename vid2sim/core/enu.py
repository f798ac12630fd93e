"""WGS-84 <-> ECEF <-> local ENU (east-north-up) through pyproj.

The geodetic-to-ECEF step is pyproj's (EPSG:4979 lat/lon/ellipsoidal height -> EPSG:4978
geocentric); the ECEF-to-ENU step is the standard rotation at the origin
(e.g. Hofmann-Wellenhof et al., GNSS, eq. 10.13):

    [e]   [ -sin(lon)            cos(lon)           0       ] [dX]
    [n] = [ -sin(lat)cos(lon)   -sin(lat)sin(lon)   cos(lat)] [dY]
    [u]   [  cos(lat)cos(lon)    cos(lat)sin(lon)   sin(lat)] [dZ]
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from vid2sim.core.records import Origin

if TYPE_CHECKING:
    from pyproj import Transformer


@lru_cache(maxsize=1)
def _geodetic_to_ecef() -> Transformer:
    # pyproj on the first conversion (50-90 ms to import after numpy, measured in-process):
    # the settings of every command import this module; `vid2sim track` / `detect` never
    # convert a coordinate.
    from pyproj import Transformer

    return Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)


@lru_cache(maxsize=1)
def _ecef_to_geodetic() -> Transformer:
    from pyproj import Transformer  # see _geodetic_to_ecef

    return Transformer.from_crs("EPSG:4978", "EPSG:4979", always_xy=True)


def geodetic_to_ecef(lat_deg, lon_deg, alt_m=0.0) -> np.ndarray:
    """WGS-84 (deg, deg, m ellipsoidal) -> (N, 3) ECEF [m]."""
    lat, lon = np.atleast_1d(np.asarray(lat_deg, float)), np.atleast_1d(np.asarray(lon_deg, float))
    alt = np.broadcast_to(np.asarray(alt_m, float), lat.shape)
    x, y, z = _geodetic_to_ecef().transform(lon, lat, alt)
    return np.column_stack((x, y, z))


def ecef_to_geodetic(ecef_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(N, 3) ECEF [m] -> latitude [deg], longitude [deg], ellipsoidal height [m]."""
    p = np.asarray(ecef_m, float).reshape(-1, 3)
    lon, lat, alt = _ecef_to_geodetic().transform(p[:, 0], p[:, 1], p[:, 2])
    return np.asarray(lat), np.asarray(lon), np.asarray(alt)


class EnuFrame:
    """A local tangent frame at ``origin``: x east, y north, z up [m]."""

    def __init__(self, origin: Origin):
        self.origin = origin
        lat, lon = math.radians(origin.lat), math.radians(origin.lon)
        sl, cl, sp, cp = math.sin(lon), math.cos(lon), math.sin(lat), math.cos(lat)
        self._r_enu_from_ecef = np.array([
            [-sl, cl, 0.0],
            [-sp * cl, -sp * sl, cp],
            [cp * cl, cp * sl, sp],
        ])
        self._origin_ecef = geodetic_to_ecef(origin.lat, origin.lon, origin.alt)[0]

    def to_enu(self, lat_deg, lon_deg, alt_m=None) -> np.ndarray:
        """Geodetic -> (N, 3) ENU [m]; a missing altitude is taken as the origin's."""
        alt = self.origin.alt if alt_m is None else alt_m
        ecef = geodetic_to_ecef(lat_deg, lon_deg, alt)
        return (ecef - self._origin_ecef) @ self._r_enu_from_ecef.T

    def to_geodetic(self, enu_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(N, 2 or 3) ENU [m] -> latitude [deg], longitude [deg], height [m]."""
        p = np.asarray(enu_m, float)
        p = p.reshape(-1, p.shape[-1] if p.ndim > 1 else p.size)
        if p.shape[1] == 2:
            p = np.column_stack((p, np.zeros(len(p))))
        ecef = p @ self._r_enu_from_ecef + self._origin_ecef
        return ecef_to_geodetic(ecef)

    def proj_string(self) -> str:
        """A PROJ string of this frame's horizontal part (a topocentric projection), for file
        headers such as OpenDRIVE's geoReference."""
        o = self.origin
        return (f"+proj=topocentric +lat_0={o.lat:.9f} +lon_0={o.lon:.9f} +h_0={o.alt:.3f} "
                "+ellps=WGS84 +units=m +no_defs")
