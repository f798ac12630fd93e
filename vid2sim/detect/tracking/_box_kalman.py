"""Constant-velocity Kalman filter on a box (centre, aspect, height), as in SORT and ByteTrack."""

from __future__ import annotations

import numpy as np

from vid2sim.core.boxes import xyah_to_xyxy, xyxy_to_xyah


class BoxKalman:
    """Constant-velocity Kalman filter on (cx, cy, a, h); time step in frames.

    Noise standard deviations are fractions of the box height per frame: 1/20 for position,
    1/160 for velocity (the values SORT/DeepSORT/ByteTrack use), a fixed small value for the
    aspect ratio, which changes slowly.
    """

    STD_POSITION = 1.0 / 20.0
    STD_VELOCITY = 1.0 / 160.0
    # A new track's state is uncertain: twice the position noise, ten times the velocity
    # noise (unknown motion), as in ByteTrack's initiate().
    INIT_POSITION_FACTOR = 2.0
    INIT_VELOCITY_FACTOR = 10.0
    STD_ASPECT = 1e-2  # aspect w/h per frame: a car's outline turns slowly
    STD_ASPECT_RATE = 1e-5  # its rate per frame
    STD_ASPECT_MEASURED = 1e-1  # a detected box's aspect is noisier than the filter's
    MIN_HEIGHT_PX = 1.0  # the state's height and the noise scale never drop below a pixel
    MIN_ASPECT = 1e-3  # nor the aspect below a sliver

    def __init__(self, box_px: np.ndarray):
        z = xyxy_to_xyah(box_px)
        self.mean = np.concatenate([z, np.zeros(4)])
        h = z[3]
        p = self.INIT_POSITION_FACTOR * self.STD_POSITION * h
        v = self.INIT_VELOCITY_FACTOR * self.STD_VELOCITY * h
        std = np.array([p, p, self.STD_ASPECT, p, v, v, self.STD_ASPECT_RATE, v])
        self.cov = np.diag(std ** 2)

    def predict(self, dt_frames: float) -> None:
        """Propagate by ``dt_frames`` frames (may be fractional or several)."""
        if dt_frames <= 0:
            return
        f = np.eye(8)
        f[:4, 4:] = np.eye(4) * dt_frames
        h = max(self.mean[3], self.MIN_HEIGHT_PX)
        std_q = np.array([self.STD_POSITION * h, self.STD_POSITION * h, self.STD_ASPECT,
                          self.STD_POSITION * h, self.STD_VELOCITY * h, self.STD_VELOCITY * h,
                          self.STD_ASPECT_RATE, self.STD_VELOCITY * h])
        self.mean = f @ self.mean
        # random-walk noise grows linearly with the elapsed frames
        self.cov = f @ self.cov @ f.T + np.diag(std_q ** 2) * dt_frames
        self.mean[3] = max(self.mean[3], self.MIN_HEIGHT_PX)
        self.mean[2] = max(self.mean[2], self.MIN_ASPECT)

    def update(self, box_px: np.ndarray) -> None:
        """Correct with a measured box (x1, y1, x2, y2) [px]."""
        z = xyxy_to_xyah(box_px)
        h = max(self.mean[3], self.MIN_HEIGHT_PX)
        r = np.diag(np.array([self.STD_POSITION * h, self.STD_POSITION * h,
                              self.STD_ASPECT_MEASURED, self.STD_POSITION * h]) ** 2)
        hm = np.zeros((4, 8))
        hm[:, :4] = np.eye(4)
        s = hm @ self.cov @ hm.T + r
        k = np.linalg.solve(s, hm @ self.cov).T
        self.mean = self.mean + k @ (z - hm @ self.mean)
        self.cov = (np.eye(8) - k @ hm) @ self.cov

    @property
    def box_px(self) -> np.ndarray:
        """Current box estimate (x1, y1, x2, y2) [px]."""
        return xyah_to_xyxy(self.mean)

    def position_std_px(self) -> tuple[float, float]:
        """One-sigma uncertainty of the box centre (x, y) [px]."""
        return float(np.sqrt(self.cov[0, 0])), float(np.sqrt(self.cov[1, 1]))
