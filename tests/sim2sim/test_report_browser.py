"""The HTML report in headless Chromium: it renders, the screenshot is not blank, every embedded plot loads.

Chromium comes from the Debian packages chromium + chromium-driver (.ci/run installs them before the tests).
"""

from __future__ import annotations

import re
import shutil
import subprocess

import numpy as np
import pytest

pytestmark = pytest.mark.slow  # a full sim2sim report in headless Chromium

FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--no-first-run", "--hide-scrollbars"]


def _chromium() -> str:
    path = shutil.which("chromium") or shutil.which("chromium-browser")
    if path is None:
        pytest.skip("chromium is not installed (apt-get install chromium chromium-driver; .ci/run does it)")
    return path


def test_report_renders_in_headless_chromium(e2e_report, tmp_path):
    import imageio.v3 as iio

    browser = _chromium()
    page = (e2e_report / "report.html").resolve().as_uri()
    shot = tmp_path / "report.png"
    run = subprocess.run([browser, *FLAGS, "--window-size=1280,2400", f"--screenshot={shot}", page],
                         capture_output=True, text=True, timeout=120)
    assert shot.is_file() and shot.stat().st_size > 20_000, run.stderr[-2000:]
    image = iio.imread(shot)
    assert image.shape[0] >= 2000 and image.shape[1] >= 1200
    gray = image[..., :3].mean(axis=-1)
    assert gray.std() > 10  # text, tables and plots, not a blank page
    assert (gray < 100).mean() > 0.005  # dark pixels: text and plot lines

    dom = subprocess.run([browser, *FLAGS, "--virtual-time-budget=5000", "--dump-dom", page],
                         capture_output=True, text=True, timeout=120).stdout
    expected = re.search(r"data-plots=['\"](\d+)['\"]", dom)
    loaded = re.search(r'data-plots-loaded="(\d+)"', dom)
    assert expected and int(expected.group(1)) >= 4, dom[:500]
    assert loaded, "the page's load handler did not run"
    assert loaded.group(1) == expected.group(1)  # every embedded PNG decoded to a non-empty image
    assert np.all([h in dom for h in ("Tracking and success", "Hand commands", "Loop timing")])
