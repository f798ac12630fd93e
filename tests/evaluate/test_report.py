"""The HTML report: self-contained, complete, and rendered by a real browser."""

from __future__ import annotations

import base64
import re
import shutil
import subprocess
from html.parser import HTMLParser

import cv2
import numpy as np
import pytest

from tests.evaluate.conftest import make_scenario
from vid2sim.base.errors import FormatError, MissingInputError
from vid2sim.core.records import AnnotatedBox, Keyframe
from vid2sim.evaluate.metrics import score_keyframes
from vid2sim.evaluate.replay import replay_boxes
from vid2sim.evaluate.report import lead_series, render_report, write_report


class _Collector(HTMLParser):
    def __init__(self):
        super().__init__()
        self.tags: list[str] = []
        self.srcs: list[str] = []
        self.hrefs: list[str] = []

    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)
        d = dict(attrs)
        if "src" in d:
            self.srcs.append(d["src"])
        if "href" in d:
            self.hrefs.append(d["href"])


def _png(color: int) -> bytes:
    ok, buf = cv2.imencode(".png", np.full((40, 60, 3), color, np.uint8))
    assert ok
    return buf.tobytes()


def _inputs():
    sc = make_scenario()
    kfs = [Keyframe(0, 0.0, "f0", [AnnotatedBox((573, 178, 646, 240), "car", "1")]),
           Keyframe(10, 1.0, "f10<&>", [])]
    m = score_keyframes(kfs, replay_boxes(sc, [0.0, 1.0], use_env=False))
    return sc, m


def test_report_is_self_contained_and_complete(tmp_path):
    sc, m = _inputs()
    fig_path = tmp_path / "extra.png"
    fig_path.write_bytes(_png(200))
    out = tmp_path / "report.html"
    write_report(out, scenario=sc, metrics=m, keyframe_images=[("kf <0>", _png(10)),
                                                                ("kf 1", _png(90))],
                 extra_figures=[("road map", fig_path)],
                 warnings=["GPS gap of 3 s <bridged>"], inputs={"video": "clip.mp4"})
    text = out.read_text(encoding="utf-8")
    p = _Collector()
    p.feed(text)
    assert "script" not in p.tags and "link" not in p.tags and "iframe" not in p.tags
    assert not p.hrefs
    # every image is embedded, none fetched: 2 keyframes (as JPEG) + map + lead + 1 extra
    assert len(p.srcs) == 5 and all(s.startswith("data:image/") for s in p.srcs)
    decoded = [base64.b64decode(s.split(",", 1)[1]) for s in p.srcs]
    assert [d[:3] == b"\xff\xd8\xff" for d in decoded] == [True, True, False, False, False]
    assert all(d[:8] == b"\x89PNG\r\n\x1a\n" for d in decoded[2:])
    without_data = re.sub(r"data:image/[a-z+]+;base64,[A-Za-z0-9+/=]+", "", text)
    assert not re.search(r"(https?:)?//[a-z]", without_data)
    for section in ("Warnings", "Inputs and assumptions", "Keyframe metrics", "Keyframes",
                    "Map and lead vehicle", "More figures"):
        assert section in text
    # user text is escaped
    assert "&lt;bridged&gt;" in text and "f10&lt;&amp;&gt;" in text and "<bridged>" not in text
    assert "built in code" in text  # the scenario's assumptions
    assert "reference study" in text


def test_report_without_metrics_and_bad_figure(tmp_path):
    sc, _ = _inputs()
    text = render_report(scenario=sc, metrics=None)
    assert "Keyframe metrics" not in text and "Map and lead vehicle" in text
    with pytest.raises(FormatError):
        render_report(scenario=sc, metrics=None, extra_figures=[("x", b"not an image")])
    with pytest.raises(MissingInputError):
        render_report(scenario=sc, metrics=None, extra_figures=[("x", tmp_path / "none.png")])


def test_lead_is_the_nearest_actor_ahead_in_the_ego_lane():
    sc = make_scenario()  # "lead" 20 m ahead closing at 2 m/s, "hidden" behind it, "left" aside
    s = lead_series(sc)
    assert set(s["lead_id"]) == {"lead"}
    # rear of the lead: 20 m - 4.3/2 at t=0, closing at 2 m/s
    assert s["range_m"][0] == pytest.approx(20.0 - 2.15, abs=1e-6)
    assert s["range_m"][-1] == pytest.approx(20.0 - 2.15 - 2.0 * 4.0, abs=1e-6)
    assert np.allclose(s["lead_speed_mps"], 8.0) and np.allclose(s["ego_speed_mps"], 10.0)


def _chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome", "chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


@pytest.mark.skipif(_chromium() is None, reason="no chromium binary on PATH "
                    "(apt-get install chromium)")
def test_report_renders_in_headless_chromium(tmp_path):
    sc, m = _inputs()
    out = tmp_path / "report.html"
    write_report(out, scenario=sc, metrics=m, keyframe_images=[("kf", _png(50))],
                 extra_figures=[], warnings=["a warning"], inputs=["one input"])
    shot = tmp_path / "shot.png"
    cmd = [_chromium(), "--headless", "--no-sandbox", "--disable-gpu",
           "--disable-background-networking", "--disable-component-update", "--disable-sync",
           "--no-first-run", f"--user-data-dir={tmp_path / 'profile'}",
           "--enable-logging=stderr", "--v=0",
           "--window-size=1280,2200", f"--screenshot={shot}", out.as_uri()]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]
    # The page logged nothing to its console (no script errors, blocked or failed loads).
    console = [line for line in proc.stderr.splitlines() if ":CONSOLE" in line]
    assert not console, console
    img = cv2.imread(str(shot))
    assert img is not None and img.shape[:2] == (2200, 1280)
    # Something was drawn: the dark header band at the top, and varied content below it
    # (a blank or error page is a single colour).
    assert img[:40].mean() < 80
    assert len(np.unique(img[200:].reshape(-1, 3), axis=0)) > 50
