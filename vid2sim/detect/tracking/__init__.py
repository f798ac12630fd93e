"""Boxes over time: the multi-object tracker, its Kalman filter, ego-motion association, optical flow."""
