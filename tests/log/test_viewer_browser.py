"""`view --web` in a real browser: a session served on loopback ports, opened in headless Chromium
(the system's, driven over the DevTools protocol by playwright; no browser is downloaded), and
the screenshot checked: both skin panels drawn (many different colours inside each), the force
plot carrying lines and the event log rows.

Runs where rerun-sdk, playwright and a Chromium executable are present (Debian: `apt-get install
chromium`; or LAYERSKIN_CHROMIUM=/path/to/chrome), and skips naming what is missing. Requests to
anything but 127.0.0.1 are aborted, so the page cannot reach the network. The screenshot is kept
under the test's tmp path and its path printed (pytest -s, or the report of a failure).

The panel boxes come from the blueprint (layout.session_layout of the session's topics: skin,
wrench and events give the maps side by side over 3/7 of the height, the force plot over the next
2/7, the events below).
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import time
import urllib.request

import numpy as np
import pytest
from viewer_sessions import write_platform_session

from layerskin_exp.log.view import rerun_view as V

pytest.importorskip("rerun", reason="rerun-sdk not installed (pip install 'layerskin-exp[view]')")
pytest.importorskip("playwright", reason="playwright not installed (the dev extra)")
from PIL import Image  # noqa: E402
from playwright.sync_api import sync_playwright  # noqa: E402

VIEWPORT = (1600, 1000)
LOAD_TIMEOUT_S = 90


def _chromium() -> str | None:
    env = os.environ.get("LAYERSKIN_CHROMIUM")
    if env:
        return env
    for name in ("chromium", "chromium-browser", "google-chrome"):
        found = shutil.which(name)
        if found:
            return found
    return None


CHROMIUM = _chromium()
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="no Chromium on PATH (apt-get install chromium, or set "
                                                         "LAYERSKIN_CHROMIUM)")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_http(url: str, proc, timeout_s: float = 30.0) -> None:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if proc.poll() is not None:
            raise AssertionError(f"view --web exited with {proc.returncode}: {proc.stdout.read()[-2000:]}")
        try:
            with urllib.request.urlopen(url, timeout=2):
                return
        except OSError:
            time.sleep(0.3)
    raise AssertionError(f"the web viewer did not answer on {url} within {timeout_s} s")


# ------------------------------------------------------------------------------ what the screenshot must show


def _boxes(w: int, h: int) -> dict[str, tuple[int, int, int, int]]:
    """(x0, y0, x1, y1) of the panels' inner parts in a screenshot (see the module docstring),
    leaving margins for the title bar, the top bar and the time panel."""
    top, bottom = int(0.04 * h), int(0.96 * h)
    row1 = top + (bottom - top) * 3 // 7
    row2 = row1 + (bottom - top) * 2 // 7
    return {"superficial": (int(0.05 * w), top + 30, int(0.45 * w), row1 - 10),
            "deep": (int(0.55 * w), top + 30, int(0.95 * w), row1 - 10),
            "force": (int(0.02 * w), row1 + 30, int(0.98 * w), row2 - 10),
            "events": (int(0.02 * w), row2 + 30, int(0.98 * w), bottom - 10)}


def _colourful(region: np.ndarray) -> np.ndarray:
    """(N, 3) pixels of strong colour: the maps' turbo and the plot lines, not the UI's greys."""
    px = region.reshape(-1, 3).astype(int)
    return px[px.max(axis=1) - px.min(axis=1) > 60]


def check_screenshot(rgb: np.ndarray) -> list[str]:
    """What is wrong with a screenshot of the served session ([] when the panels are drawn)."""
    problems = []
    h, w = rgb.shape[:2]
    boxes = _boxes(w, h)
    for layer in ("superficial", "deep"):
        x0, y0, x1, y1 = boxes[layer]
        c = _colourful(rgb[y0:y1, x0:x1])
        area = (x1 - x0) * (y1 - y0)
        colours = len({tuple(p) for p in c[:: max(1, len(c) // 20000)]})
        if len(c) < 0.2 * area or colours < 12:
            problems.append(f"{layer} panel not drawn: {len(c)} coloured pixels of {area}, {colours} colours")
    x0, y0, x1, y1 = boxes["force"]
    c = _colourful(rgb[y0:y1, x0:x1])
    if len(c) < 800:  # the legend's dots alone are a few hundred
        problems.append(f"force plot has no data drawn: {len(c)} coloured pixels")
    x0, y0, x1, y1 = boxes["events"]
    text = int((rgb[y0:y1, x0:x1].astype(int).sum(axis=2) < 300).sum())
    if text < 150:  # a header row and two events are thousands
        problems.append(f"event log shows no rows: {text} dark pixels")
    return problems


def test_the_checks_fail_on_a_blank_panel_and_an_empty_plot():
    rgb = np.full((VIEWPORT[1], VIEWPORT[0], 3), 245, np.uint8)
    problems = check_screenshot(rgb)
    assert len(problems) == 4 and "superficial" in problems[0] and "force" in problems[2] and "event" in problems[3]


# ------------------------------------------------------------------------------ the browser


def test_view_web_shows_both_skin_maps_and_the_force_plot_in_headless_chromium(tmp_path):
    session = write_platform_session(tmp_path / "press.mcap")
    port, grpc = _free_port(), _free_port()
    proc = subprocess.Popen([sys.executable, "-m", "layerskin_exp.log", "view", str(session), "--web",
                             "--port", str(port), "--grpc-port", str(grpc)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    shot = tmp_path / "viewer.png"
    try:
        _wait_http(f"http://127.0.0.1:{port}/", proc)
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=[
                "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist"])
            try:
                page = browser.new_page(viewport={"width": VIEWPORT[0], "height": VIEWPORT[1]})
                page.route("**/*", lambda route: route.continue_() if route.request.url.startswith(
                    ("http://127.0.0.1", "ws://127.0.0.1", "data:", "blob:")) else route.abort())
                page.goto(V.web_address(port, grpc))
                page.wait_for_selector("canvas", timeout=30_000)
                end, problems = time.monotonic() + LOAD_TIMEOUT_S, ["not loaded"]
                while problems and time.monotonic() < end:  # the viewer has loaded when the panels are drawn
                    time.sleep(2.0)
                    page.screenshot(path=str(shot))
                    problems = check_screenshot(np.asarray(Image.open(shot).convert("RGB")))
            finally:
                browser.close()
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
    print(f"viewer screenshot: {shot}")
    assert problems == [], f"{problems} (screenshot: {shot})"
