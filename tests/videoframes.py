"""Decode a whole (short) test video into memory: the tests' check of what a writer wrote."""

from __future__ import annotations

import cv2


def decoded_frames(path) -> list:
    """Every frame OpenCV decodes from ``path``, in order."""
    cap = cv2.VideoCapture(str(path))
    out = []
    while True:
        ok, img = cap.read()
        if not ok:
            break
        out.append(img)
    cap.release()
    return out
