"""Writing a generated clip with OpenCV: into a hidden file beside the output, renamed over
it only when every frame was written (:func:`vid2sim.base.fileio.atomic_path`), so a failed
generation never leaves a half-written clip where a test or benchmark looks for one."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path

import cv2

from vid2sim.base.errors import OutputError
from vid2sim.base.fileio import atomic_path


@contextlib.contextmanager
def staged_video(out_path: Path, size: tuple[int, int], fps: float) -> Iterator[cv2.VideoWriter]:
    """An OpenCV writer of ``size`` (width, height) frames at ``fps``: MPEG-4 part 2 for an
    ``.mp4`` path, Motion-JPEG otherwise (every OpenCV build decodes both)."""
    out_path = Path(out_path)
    fourcc = "mp4v" if out_path.suffix.lower() == ".mp4" else "MJPG"
    with atomic_path(out_path) as tmp:
        writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*fourcc), fps, size)
        try:
            if not writer.isOpened():
                raise OutputError(out_path, f"OpenCV cannot write {fourcc} video here",
                                  "choose a writable .mp4 or .avi path")
            yield writer
        finally:
            writer.release()
