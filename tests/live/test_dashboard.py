"""The dashboard in a real browser (headless Chromium): it loads, updates, and shows the
alarm after a payload change. Skipped, with the reason, where no browser is installed."""

from __future__ import annotations

import contextlib
import os
import re
import select
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from ehss.live.dashboard import Dashboard

SRC = str(Path(__file__).resolve().parents[2] / "src")
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
DRIVER = shutil.which("chromedriver")

_STATE_JS = """
const doc = (window.Bokeh && Bokeh.documents.length) ? Bokeh.documents[0] : null;
if (!doc) return null;
const get = (name) => doc.get_model_by_name(name);
return [get('status').text, get('alarms').text, get('bode_model').data.mag.slice(0, 4)];
"""


def test_exposed_dashboard_needs_a_token():
    local = Dashboard(host="127.0.0.1", port=5006)
    assert local.token is None and local.url == "http://127.0.0.1:5006/"
    exposed = Dashboard(host="10.1.2.3", port=5006)   # not started: nothing is bound
    assert exposed.token and exposed.url.endswith(f"?token={exposed.token}")


_NEEDS_BROWSER = pytest.mark.skipif(
    CHROMIUM is None or DRIVER is None,
    reason="no headless browser: install Debian's chromium and chromium-driver (make test "
    "does so when run as root)")


def _browser():
    webdriver = pytest.importorskip("selenium.webdriver")
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    opts = Options()
    opts.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
                "--window-size=1200,1150"):
        opts.add_argument(arg)
    return webdriver.Chrome(service=Service(DRIVER), options=opts)


def _drain(stream) -> None:
    with contextlib.suppress(OSError, ValueError):   # closed by _stop
        while stream.read(4096):
            pass


def _start_live(argv: list[str]) -> tuple[subprocess.Popen, str | None]:
    """``ehss live ARGV`` in its own process, and the dashboard's URL once printed."""
    env = dict(os.environ, PYTHONPATH=SRC + os.pathsep + os.environ.get("PYTHONPATH", ""))
    live = subprocess.Popen([sys.executable, "-m", "ehss", "live", *argv], env=env,
                            stderr=subprocess.PIPE, text=True)
    url = None
    deadline = time.monotonic() + 120
    while url is None and time.monotonic() < deadline:
        if not select.select([live.stderr], [], [], 0.5)[0]:
            continue
        line = live.stderr.readline()
        if not line and live.poll() is not None:
            break
        m = re.search(r"dashboard at (http://127\.0\.0\.1:\d+/)", line)
        url = m.group(1) if m else None
    # the rest of its log is read as it comes, so that a full pipe never holds it up
    threading.Thread(target=_drain, args=(live.stderr,), daemon=True).start()
    return live, url


def _open(driver, url: str | None, live: subprocess.Popen) -> None:
    assert url, "the dashboard did not start"
    driver.set_page_load_timeout(60)
    page = ""
    for _ in range(5):
        # on a loaded machine the browser sometimes reports the load of an empty page
        # before the server's answer: ask again
        driver.get(url)
        page = driver.page_source
        if page:
            break
        time.sleep(2)
    # BokehJS comes from the ehss server itself, not from a CDN
    scripts = re.findall(r'<script[^>]+src="([^"]+)"', page)
    assert scripts and all(s.startswith("/static/") for s in scripts), \
        (scripts, live.poll(), page[:300])


def _stop(driver, live: subprocess.Popen) -> None:
    driver.quit()
    live.terminate()
    live.wait(20)
    assert live.stderr is not None
    live.stderr.close()


@pytest.mark.slow
@pytest.mark.realtime
@_NEEDS_BROWSER
def test_dashboard_in_headless_chromium(tmp_path):
    # the browser first (slow to start on a loaded machine), then the rig
    driver = _browser()
    live, url = _start_live(["--rig", "position", "--channels", "2", "--duration", "30",
                             "--event", "8:mass_kg=350@1", "--learn", "4", "--speed", "2",
                             "--dashboard", "0", "--quiet"])
    try:
        _open(driver, url, live)
        seen = []
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:
            state = driver.execute_script(_STATE_JS)
            if state and state[0].startswith("<b>t ="):
                seen.append(state)
                if "ALARM" in state[1] and len(seen) > 5:
                    break
            time.sleep(0.5)
        assert seen, "the page never showed data"
        times = {re.search(r"t = ([0-9.]+) s", s[0]).group(1) for s in seen}
        # the status kept updating (on a loaded machine a refresh may take seconds)
        assert len(times) >= 2
        bodes = {tuple(s[2]) for s in seen if s[2]}
        assert len(bodes) > 1                        # the Bode plot of the model moved
        alarm = seen[-1][1]
        # the log also lists each channel's messages (detection started): judge the
        # alarm entries alone, which must name channel 1 and never channel 2
        alarms = [e for e in alarm.split("<br>") if "<b>ALARM</b>" in e]
        assert alarms and all("channel 1 " in e for e in alarms), alarms
        assert not any("channel 2 " in e for e in alarms), alarms
        t_alarm = float(re.search(r"ALARM</b></span> t = ([0-9.]+) s", alarm).group(1))
        assert 8.0 < t_alarm <= 9.0
        driver.save_screenshot(str(tmp_path / "dashboard.png"))
    finally:
        _stop(driver, live)


_COMPENSATION_JS = """
const doc = (window.Bokeh && Bokeh.documents.length) ? Bokeh.documents[0] : null;
if (!doc) return null;
const get = (name) => doc.get_model_by_name(name);
const err = get('compensation_error').data, inv = get('compensation_inverse').data;
return [get('compensation_log').text, get('compensation_log').visible,
        Array.from(err['with']), Array.from(err['without']), Array.from(inv.mag),
        Array.from(inv.f)];
"""


@pytest.mark.slow
@pytest.mark.realtime
@_NEEDS_BROWSER
def test_compensation_panel_in_headless_chromium(tmp_path):
    driver = _browser()
    live, url = _start_live(["--rig", "position", "--duration", "30", "--band", "0.5", "20",
                             "--rms", "0.0005", "--compensate", "preview", "--speed", "2",
                             "--dashboard", "0", "--quiet", "--record",
                             str(tmp_path / "run.h5")])
    try:
        _open(driver, url, live)
        state = None
        deadline = time.monotonic() + 150
        while time.monotonic() < deadline:
            state = driver.execute_script(_COMPENSATION_JS)
            # 10 s of stretches, the first inverse loaded at 2 s and in well before
            if state and state[4] and len(state[2]) > 40:
                break
            time.sleep(0.5)
        assert state and state[1], f"the compensation panel never showed: {state}"
        text, _, with_, without, mag, f = state
        assert "channel 1:" in text and "loaded" in text, text
        assert len(with_) > 40, f"only {len(with_)} stretches shown"
        # the inverse's response spans the band; over the latest 2 s the error is far
        # below the rig's without compensation (about 60 times on this rig)
        assert mag and 0.5 <= min(f) and max(f) <= 20.0 * (1 + 1e-9)
        recent = slice(-8, None)
        assert np.median(with_[recent]) < np.median(without[recent]) / 2, (with_, without)
        driver.save_screenshot(str(tmp_path / "compensation.png"))
    finally:
        _stop(driver, live)


def test_compensation_panel_names_a_flagged_change_and_its_correction():
    # the panel reads each event as a user would: a change flagged and the correction
    # that follows it, not the raw kinds of the log
    from ehss.live import dashboard
    from ehss.live.snapshot import ChannelCompensation, CompensationSnapshot

    ch = ChannelCompensation(name="1", t=np.zeros(0), error_rms=np.zeros(0),
                             error_rms_without=np.zeros(0), freq_hz=np.zeros(0),
                             inverse=None, loads=2, refusals=0, last_reason="",
                             model="correction")
    comp = CompensationSnapshot(mode="preview", band_hz=(0.5, 20.0), channels=(ch,))
    events = [{"kind": "compensator", "channel": "1", "t_s": 2.0, "model": "estimator"},
              {"kind": "compensator_change", "channel": "1", "t_s": 20.4},
              {"kind": "compensator", "channel": "1", "t_s": 21.3, "model": "correction"}]
    page = dashboard._compensation_html(comp, events)
    assert "compensator_change" not in page
    assert "t = 20.40 s &nbsp; channel 1: change flagged" in page
    assert "t = 21.30 s &nbsp; channel 1: correction of the running compensator" in page
    assert "t = 2.00 s &nbsp; channel 1: loaded" in page
