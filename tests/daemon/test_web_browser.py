"""``avard web`` in a real browser: headless Chromium (Debian's ``chromium`` and
``chromium-driver``, installed by ``.ci/install-browser``) driven by Selenium.

Starts ``avard run --simulate quiet-lab`` (20× real time) and ``avard web`` as processes on
free loopback ports, opens the page and checks what a user would: the ADEV plot shows points
for every axis, the page updates without a reload, a gap injected in the service (a restart:
SIGTERM, then ``avard run`` again on the same data directory, which continues the sample
index and records a ``restart`` gap) appears on the time line, nothing is loaded from
anywhere but avard, and the page fits a phone's width. Screenshots (desktop and phone) are
written to the test's tmp directory, or to ``$AVARD_WEB_SCREENSHOTS`` when set.

Skips, saying why, only where no browser can be had; under CI (``CI=true``) a missing
browser fails instead.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from .web_rig import WebRig

CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                  "--no-first-run", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync")


def _missing() -> str | None:
    try:
        import selenium  # noqa: F401
    except ImportError:
        return "selenium is not installed (make .venv/.installed-test installs it)"
    for exe, pkg in (("chromium", "chromium"), ("chromedriver", "chromium-driver")):
        if shutil.which(exe) is None:
            return f"no {exe} on PATH: run .ci/install-browser (apt-get install {pkg})"
    return None


@pytest.fixture
def browser(tmp_path: Path) -> Iterator[Any]:
    reason = _missing()
    if reason is not None:
        if os.environ.get("CI") == "true":
            pytest.fail(f"CI must run the browser test: {reason}")
        pytest.skip(reason)
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = shutil.which("chromium") or "chromium"
    for flag in (*CHROMIUM_FLAGS, "--window-size=1280,900",
                 f"--user-data-dir={tempfile.mkdtemp(dir=tmp_path)}"):
        opts.add_argument(flag)
    driver = webdriver.Chrome(service=Service(shutil.which("chromedriver")), options=opts)
    try:
        yield driver
    finally:
        driver.quit()


@pytest.fixture
def rig(tmp_path: Path) -> Iterator[WebRig]:
    r = WebRig(tmp_path, speed=20.0, web_args=("--fit-interval", "2", "--refresh", "0.5"))
    try:
        yield r
    finally:
        r.close()


def page_text(browser: Any, css: str) -> str:
    """The text of the first element matching ``css``, read in one script call: the page
    replaces its sections on every update, so an element found by one WebDriver call may be
    gone (stale) by the next."""
    return browser.execute_script(
        "const e = document.querySelector(arguments[0]); return e ? e.innerText : '';", css)


def page_updates(browser: Any) -> int:
    return int(browser.execute_script("return document.body.dataset.updates || 0"))


def wait_for(what: str, cond: Callable[[], Any], timeout: float, rig: WebRig,
             browser: Any = None) -> Any:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = cond()
        if value:
            return value
        time.sleep(0.25)
    page = ""
    if browser is not None:  # what the page showed, for the failure report
        shot = rig.tmp / "timeout.png"
        browser.save_screenshot(str(shot))
        page = (f"page: updates {page_updates(browser)}, connection "
                f"{page_text(browser, '#conn')!r}, screenshot {shot}\n"
                f"{page_text(browser, 'main')[:3000]}\n")
    raise AssertionError(f"timed out after {timeout:g} s waiting for {what}\n{page}"
                         f"state {rig.state()}\n{rig.read_logs()}")


POINTS_JS = """
const out = {};
for (const g of document.querySelectorAll('#adev g.adev-axis')) {
  out[g.dataset.axis] = g.querySelectorAll('circle.pt').length;
}
return out;"""

ITEMS_JS = """
return Array.from(document.querySelectorAll('#timeline g.tl-item'))
  .map(g => g.dataset.kind + ':' + g.dataset.name);"""


OVERLAPS_JS = """
const out = [];
for (const svg of document.querySelectorAll('svg')) {
  const ts = [...svg.querySelectorAll('text')]
    .map(t => [t.textContent, t.getBoundingClientRect()]).filter(x => x[1].width > 0);
  for (let i = 0; i < ts.length; i++) for (let j = i + 1; j < ts.length; j++) {
    const a = ts[i][1], b = ts[j][1];
    if (a.left < b.right - 0.5 && b.left < a.right - 0.5 && a.top < b.bottom - 0.5
        && b.top < a.bottom - 0.5) out.push([svg.getAttribute('class'), ts[i][0], ts[j][0]]);
  }
}
return out;"""

FIRST_LOAD_JS = """
const n = performance.getEntriesByType('navigation')[0];
return {response_ms: n.responseEnd - n.requestStart, load_ms: n.loadEventEnd,
        resources: performance.getEntriesByType('resource').map(e => e.name)
          .filter(u => !u.endsWith('/favicon.ico') && !u.includes('/events'))};"""


def screenshot_dir(tmp_path: Path) -> Path:
    d = Path(os.environ.get("AVARD_WEB_SCREENSHOTS") or tmp_path)
    d.mkdir(parents=True, exist_ok=True)
    return d


def test_the_page_shows_the_run_live_in_a_real_browser(browser, rig, tmp_path):
    rig.start_service()
    rig.start_web()
    browser.get(rig.url)
    assert browser.title.startswith("avard")

    # ADEV points for every axis
    points = wait_for("ADEV points for x, y and z",
                      lambda: (p := browser.execute_script(POINTS_JS))
                      and all(p.get(a, 0) > 0 for a in "xyz") and p, 90, rig, browser)
    assert set(points) == {"x", "y", "z"}

    # it updates without a reload: new SSE updates, and a newer snapshot in the plot
    marker = browser.execute_script("window.__sameDocument = 1; return 1")
    note = page_text(browser, "#adev p.note")
    updates = page_updates(browser)
    wait_for("a newer Allan snapshot on the page",
             lambda: page_text(browser, "#adev p.note") != note
             and page_updates(browser) >= updates + 2, 60, rig, browser)
    assert browser.execute_script("return window.__sameDocument") == marker  # no reload
    assert "live" in browser.execute_script("return document.getElementById('conn').className")

    # the fit: IEEE term rows with values, and a model curve per axis
    wait_for("the fitted terms",
             lambda: page_text(browser, "#fit tr[data-term='velocity_random_walk']"), 60, rig,
             browser)
    wait_for("model curves", lambda: len(browser.find_elements(
        "css selector", "#adev g.adev-axis path.model")) == 3, 60, rig, browser)
    vrw = page_text(browser, "#fit tr[data-term='velocity_random_walk']")
    assert "absent" not in vrw and "e-0" in vrw, vrw

    # a gap injected in the service: restart it on the same data directory
    assert not any(i.startswith("gap:") for i in browser.execute_script(ITEMS_JS))
    rig.stop_service()
    rig.start_service()
    items = wait_for("the restart gap on the time line",
                     lambda: (i := browser.execute_script(ITEMS_JS)) and "gap:restart" in i
                     and i, 90, rig, browser)
    assert "event:new run" in items
    timeline = page_text(browser, "#timeline")
    assert "restart" in timeline

    # nothing from anywhere but avard itself
    origin = rig.url.rstrip("/")
    resources = browser.execute_script(
        "return performance.getEntriesByType('resource').map(e => e.name)")
    assert resources and all(r.startswith(origin) for r in resources), resources

    shots = screenshot_dir(tmp_path)
    height = browser.execute_script("return document.body.scrollHeight")
    browser.set_window_size(1280, min(height + 120, 4000))
    browser.save_screenshot(str(shots / "avard-web.png"))

    # no two labels of a plot overlap, on a wide screen and on phones (the phone's larger
    # text once ran tick labels into axis labels and "gaps" into "events" at 412 px)
    assert browser.execute_script(OVERLAPS_JS) == []

    # phone width: no sideways scrolling, the plots scale to the screen
    for width in (412, 390):
        browser.set_window_size(width, 844)
        wait_for(f"the layout at {width} px", lambda w=width: browser.execute_script(
            "return window.innerWidth") <= w, 30, rig, browser)
        widths = browser.execute_script(
            "return [document.documentElement.scrollWidth, window.innerWidth, "
            "document.querySelector('#adev svg').getBoundingClientRect().width]")
        assert widths[0] <= widths[1] + 1, widths
        assert 250 < widths[2] <= widths[1], widths
        assert browser.execute_script(OVERLAPS_JS) == [], width
    browser.save_screenshot(str(shots / "avard-web-phone.png"))

    # The temperature card says what it covers: this avard web started without --history.
    assert "Since avard web started" in page_text(browser, "#temps")

    # A first load needs nothing but the page and its two files, and the page as served
    # already shows the run (ADEV points, the fit) without waiting for a live update. How
    # long it took is reported, not asserted (no wall-time assertions on a shared machine;
    # about 0.5 s to the load event on the loaded 2-core machine, 2026-11-27).
    import urllib.request

    with urllib.request.urlopen(rig.url, timeout=60) as r:
        served = r.read().decode()
    assert 'class="pt"' in served and "data-term=" in served
    browser.get(rig.url + "?fresh=1")
    first = browser.execute_script(FIRST_LOAD_JS)
    assert sorted(first["resources"]) == [f"{origin}/static/app.js",
                                          f"{origin}/static/style.css"], first
    print(f"first load: response {first['response_ms']:.0f} ms, load event "
          f"{first['load_ms']:.0f} ms")
