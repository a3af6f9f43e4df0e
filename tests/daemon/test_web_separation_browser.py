"""The self-noise-against-common-mode card in a real browser (headless Chromium, as
tests/daemon/test_web_browser.py): at 1280, 412 and 390 px the page does not scroll sideways,
each axis's plot fits its card, and no two labels of a plot overlap. The page is the one
``avard web`` serves (app.page_html) for a state holding a decoded live separation, opened
from a file with its stylesheet inlined (layout only; the live path is test_web_browser's).
Skips where no browser can be had, as that test does."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from .test_web_browser import OVERLAPS_JS, browser, screenshot_dir  # noqa: F401
from .test_web_separation import _live_record

STYLE = Path(__file__).resolve().parents[2] / "daemon" / "web" / "static" / "style.css"

SIZES_JS = """
const out = {scroll: document.documentElement.scrollWidth, inner: window.innerWidth,
             plots: []};
for (const d of document.querySelectorAll('#separation .sep-axis')) {
  const svg = d.querySelector('svg').getBoundingClientRect();
  const card = d.closest('section').getBoundingClientRect();
  out.plots.push([d.dataset.axis, svg.width, svg.left - card.left, card.right - svg.right]);
}
return out;"""


def test_the_separation_card_fits_a_wide_screen_and_phones(browser: Any,  # noqa: F811
                                                           tmp_path: Path) -> None:
    from avard.daemon.web.app import Hub, page_html
    from avard.daemon.web.state import RunState

    rec, _sep = _live_record(1 << 14)
    state = RunState()
    state.set_snapshot(rec)
    html = page_html(state, Hub(state), 0.1, "tcp://127.0.0.1:1")
    html = html.replace('<link rel="stylesheet" href="/static/style.css">',
                        f"<style>{STYLE.read_text()}</style>")
    html = html.replace('<script src="/static/app.js" defer></script>', "")
    page = tmp_path / "page.html"
    page.write_text(html)
    shots = screenshot_dir(tmp_path)
    for width in (1280, 412, 390):
        browser.set_window_size(width, 900)
        browser.get(page.as_uri())
        got = browser.execute_script(SIZES_JS)
        browser.execute_script("document.querySelector('#separation').scrollIntoView()")
        browser.save_screenshot(str(shots / f"separation-{width}.png"))
        assert got["scroll"] <= got["inner"] + 1, (width, got)
        assert [p[0] for p in got["plots"]] == ["x", "y", "z"]
        for _axis, w, left, right in got["plots"]:
            assert 240 < w <= got["inner"], (width, got)
            assert left >= 0 and right >= 0, (width, got)      # inside its card
        assert browser.execute_script(OVERLAPS_JS) == [], width
