"""The HTTP side of ``avard web`` (aiohttp): the page, its live updates, ``/metrics``.

Routes (GET/HEAD only — the page controls nothing; any other method gets 405):

* ``/``: the whole page with every fragment filled in, so a late viewer (or a browser without
  JavaScript) sees the run so far at once; ``?target=P`` sets the target interval half-width
  in percent for the time-to-target tables;
* ``/events``: server-sent events; every ``refresh_s`` with news, one ``update`` event whose
  data is a JSON map fragment id → HTML (``static/app.js`` swaps them in): all fragments
  first, then those that changed;
* ``/metrics``: Prometheus text format (:mod:`.metrics`);
* ``/state.json``: a few numbers for scripts and tests;
* ``/static/…``: the page's own script and style (nothing is loaded from elsewhere; the
  Content-Security-Policy header says so to the browser too).

Fragments are rendered once per change, not once per viewer: :class:`Hub` renders on a timer
when the state's version moved, and every viewer's stream writes the same bytes (one render
per distinct target). A slow viewer simply skips to the newest version.
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
import time
from dataclasses import dataclass, field
from html import escape
from importlib import resources
from typing import Any

from aiohttp import web
from avard.daemon.web import render
from avard.daemon.web.metrics import CONTENT_TYPE, metrics_text
from avard.daemon.web.state import RunState

log = logging.getLogger(__name__)

DEFAULT_TARGET = 0.1
KEEPALIVE_S = 15.0
IDLE_REFRESH_S = 5.0
STATIC = {"app.js": "text/javascript", "style.css": "text/css"}
SECURITY_HEADERS = {
    "Content-Security-Policy": "default-src 'none'; script-src 'self'; style-src 'self'; "
                               "img-src 'self' data:; connect-src 'self'; form-action 'self'; "
                               "base-uri 'none'; frame-ancestors 'none'",
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
}


def parse_target(query: Any) -> float:
    """``?target=P`` (percent, 0.1–100) as a fraction; the default for anything else."""
    raw = query.get("target")
    try:
        pct = float(raw)
    except (TypeError, ValueError):
        return DEFAULT_TARGET
    return pct / 100.0 if math.isfinite(pct) and 0.1 <= pct <= 100 else DEFAULT_TARGET


@dataclass
class Hub:
    """Renders the state's fragments when it changed and hands them to every viewer.

    A viewer that has the previous version gets only the fragments that changed since (the
    ADEV plot and the tables change with a snapshot, every 10 s by default; status and
    temperatures every second); one that joined or fell behind gets them all.
    """

    state: RunState
    refresh_s: float = 1.0
    viewers: int = 0
    seq: int = 0
    common: dict[str, str] = field(default_factory=dict)
    closing: bool = False
    _seen_version: int = -1
    _rendered_at: float = -math.inf
    _changed: set[str] = field(default_factory=set)
    # target → (seq it was rendered at, its fragments, which of them changed from seq − 1)
    _targets: dict[float, tuple[int, dict[str, str], set[str]]] = field(default_factory=dict)
    _cache: dict[tuple[float, bool], bytes] = field(default_factory=dict)
    _cond: asyncio.Condition | None = None

    def condition(self) -> asyncio.Condition:
        if self._cond is None:
            self._cond = asyncio.Condition()
        return self._cond

    def refresh(self) -> bool:
        """Render the target-independent fragments anew if the state changed, or at least
        every ``IDLE_REFRESH_S`` (ages on the page advance, and a silent service shows)."""
        now = time.monotonic()
        with self.state.lock:
            if self.state.version == self._seen_version \
                    and now - self._rendered_at < IDLE_REFRESH_S:
                return False
            self._seen_version, self._rendered_at = self.state.version, now
            new = render.common_fragments(self.state)
        self._changed = {k for k, v in new.items() if self.common.get(k) != v}
        self.common = new
        self._cache = {}
        self.seq += 1
        # targets nobody asked for since the previous version are forgotten (bounded memory)
        self._targets = {t: v for t, v in self._targets.items() if v[0] >= self.seq - 1}
        return True

    def target_parts(self, target: float) -> tuple[dict[str, str], set[str]]:
        """This version's fragments for ``target`` and those that changed from the last."""
        seq, parts, changed = self._targets.get(target, (-1, {}, set()))
        if seq != self.seq:
            with self.state.lock:
                new = render.target_fragments(self.state, target)
            changed = ({k for k, v in new.items() if parts.get(k) != v}
                       if seq == self.seq - 1 else set(new))
            parts = new
            self._targets[target] = (self.seq, parts, changed)
        return parts, changed

    def payload(self, target: float, *, delta: bool = False) -> bytes:
        """The SSE ``update`` event of the current version for this target: every fragment,
        or (``delta``) those changed since the previous version; b"" when none did."""
        key = (target, delta)
        data = self._cache.get(key)
        if data is None:
            if not self.common:
                self.refresh()
            tparts, tchanged = self.target_parts(target)
            if delta:
                parts = {**{k: self.common[k] for k in self._changed},
                         **{k: tparts[k] for k in tchanged}}
            else:
                parts = {**self.common, **tparts}
            data = f"event: update\ndata: {json.dumps(parts)}\n\n".encode() if parts else b""
            self._cache[key] = data
        return data

    async def run(self) -> None:
        """Poll the state every ``refresh_s``; wake the viewers when it changed."""
        cond = self.condition()
        while not self.closing:
            if self.refresh():
                async with cond:
                    cond.notify_all()
            await asyncio.sleep(self.refresh_s)

    async def wait(self, seen: int, timeout: float) -> bool:
        """True when a version newer than ``seen`` is ready, False after ``timeout``."""
        cond = self.condition()
        async with cond:
            try:
                await asyncio.wait_for(cond.wait_for(lambda: self.seq != seen or self.closing),
                                       timeout)
            except TimeoutError:
                return False
        return self.seq != seen

    async def close(self) -> None:
        self.closing = True
        cond = self.condition()
        async with cond:
            cond.notify_all()


def page_html(state: RunState, hub: Hub, target: float, endpoint: str) -> str:
    hub.payload(target)  # renders what is missing
    parts = {**hub.common, **hub.target_parts(target)[0]}
    sections = [
        ("status", "Status", ""),
        ("adev", "Allan deviation", ""),
        ("separation", "Self-noise against common mode", ""),
        ("fit", "Fitted noise terms", ""),
        ("targets", "Time until each τ is known", _target_form(target)),
        ("temps", "Temperatures", ""),
        ("timeline", "Gaps and events", ""),
    ]
    body = "".join(
        f'<section class="card {sid}"><h2>{title}</h2>{extra}<div id="{sid}">{parts[sid]}'
        f"</div></section>" for sid, title, extra in sections)
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>avard web — {escape(endpoint)}</title>
<link rel="stylesheet" href="/static/style.css">
<script src="/static/app.js" defer></script>
</head><body data-updates="0">
<header><h1>avard <small>{escape(endpoint)}</small></h1>
<p id="conn" class="down">static view (live updates need JavaScript)</p>
<p class="note">Read-only view; SI units (s, Hz, m/s², °C).</p></header>
<main>{body}</main>
</body></html>
"""


def _target_form(target: float) -> str:
    return (f'<form class="target" method="get" action="/"><label>target ±<input '
            f'name="target" type="number" min="0.1" max="100" step="any" '
            f'value="{100 * target:.3g}"> %</label> <button type="submit">set</button></form>')


def _report_end(task: asyncio.Task[None]) -> None:
    """The hub's timer must not die unnoticed (pages would silently stop updating)."""
    if not task.cancelled() and task.exception() is not None:
        log.error("live updates stopped: %r", task.exception())


@web.middleware
async def _headers(request: web.Request, handler: Any) -> web.StreamResponse:
    resp: web.StreamResponse = await handler(request)
    for k, v in SECURITY_HEADERS.items():
        resp.headers.setdefault(k, v)
    return resp


def make_app(state: RunState, hub: Hub, *, endpoint: str = "") -> web.Application:
    """The aiohttp application over ``state`` (the hub's timer starts with the app)."""
    app = web.Application(middlewares=[_headers])
    static = {name: resources.files(__package__).joinpath("static", name).read_bytes()
              for name in STATIC}

    async def index(request: web.Request) -> web.Response:
        html = page_html(state, hub, parse_target(request.query), endpoint)
        return web.Response(text=html, content_type="text/html",
                            headers={"Cache-Control": "no-store"})

    async def events(request: web.Request) -> web.StreamResponse:
        target = parse_target(request.query)
        resp = web.StreamResponse(headers={"Content-Type": "text/event-stream",
                                           "Cache-Control": "no-store",
                                           "X-Accel-Buffering": "no"})
        await resp.prepare(request)
        hub.viewers += 1
        try:
            await resp.write(b"retry: 3000\n\n")
            seen = -1
            while not hub.closing:
                if hub.seq != seen:
                    delta, seen = seen == hub.seq - 1, hub.seq
                    data = hub.payload(target, delta=delta)
                    if data:
                        await resp.write(data)
                elif not await hub.wait(seen, KEEPALIVE_S):
                    await resp.write(b": keep-alive\n\n")
        except (ConnectionResetError, ConnectionError):
            pass  # the viewer went away
        finally:
            hub.viewers -= 1
        return resp

    async def metrics(_request: web.Request) -> web.Response:
        with state.lock:
            text = metrics_text(state)
        return web.Response(body=text.encode(), headers={"Content-Type": CONTENT_TYPE})

    async def state_json(_request: web.Request) -> web.Response:
        with state.lock:
            snap = state.snapshot
            doc = {"version": state.version, "runs": list(state.runs),
                   "samples_received": state.stats.samples_received,
                   "messages_lost": state.stats.messages_lost,
                   "samples_lost": state.stats.samples_lost,
                   "allan_samples": snap.n_samples if snap else 0,
                   "fitted": bool(state.fits), "viewers": hub.viewers,
                   "gaps_by_reason": dict(state.gaps_by_reason),
                   "events_by_name": dict(state.events_by_name)}
        return web.json_response(doc)

    async def static_file(request: web.Request) -> web.Response:
        name = request.match_info["name"]
        if name not in static:
            raise web.HTTPNotFound()
        return web.Response(body=static[name], headers={
            "Content-Type": f"{STATIC[name]}; charset=utf-8", "Cache-Control": "max-age=300"})

    async def start_hub(_app: web.Application) -> Any:
        task = asyncio.create_task(hub.run())
        task.add_done_callback(_report_end)
        yield
        await hub.close()
        task.cancel()

    app.router.add_get("/", index)
    app.router.add_get("/events", events)
    app.router.add_get("/metrics", metrics)
    app.router.add_get("/state.json", state_json)
    app.router.add_get("/static/{name}", static_file)
    app.cleanup_ctx.append(start_hub)
    return app
