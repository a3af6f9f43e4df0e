"""Which transients the compound search reads from a thermal path's own switches.

A path beyond one lag whose extension switches (a relay flips at each of the temperature's
turns, a dT/dt term's sign does, a quadratic or a second path rises and falls twice a
cycle) leaves in the axis as recorded a level that jumps at times the drive sets. The
compound search (``transients.find_compound``), run on that axis, reads those jumps as bias
steps and excursions: on a record with a relay at c < 0 it found an excursion per
cycle, each edge within a minute or so of a relay switch.
``engine.thermal._beside_transients`` tests a path whose extension is the whole claim beside the
transients found on the axis, and a relay tested beside its own switches predicts no better
than they do: the relay was lost, and the switches claimed as excursions.

A record's genuine transients fall where they fall: an edge lands near one of the path's
switches of the same sign and size only by chance, at the share of the record such
switches cover (``chance``). So the edges are counted against that chance
(``locked_to_path``): where more of them sit on the path's switches than chance would place
there (a Poisson-binomial tail, Bonferroni-split at ``LOCK_ALPHA`` over the θ of the
path's grid: the fit chose its lag and width among them, each of which places the switches
elsewhere, so the count is the best of that many), the transients whose every edge sits on
a switch are the path's own and are not held beside it as nuisance; the others still are.
With few edges (the 1 h record a relay's two or three switches fitted onto a warm-up's and
a step's place) no count can pass, and every transient stays beside the path as before.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from itertools import pairwise
from typing import NamedTuple

import numpy as np
from avard.core.explain import alarm
from avard.core.explain import causes as cz
from avard.core.explain.thermal_fit import ThermalFit
from avard.core.explain.thermal_paths.columns import quadratic_leads, trials
from avard.core.explain.thermal_paths.settings import LAG_GRID_S
from numpy.typing import NDArray

#: the level at which edges on the path's switches are more than chance: the count's own
#: share of the axis's level (``alarm.PATH_SWITCHES``): a false lock leaves genuine
#: transients out of the test the path must pass beside them
LOCK_ALPHA = alarm.PATH_SWITCHES
#: an edge and a switch are of one size when their jumps are within this factor of each
#: other (the relay's h and the search's excursion sizes differ by what each fit absorbs)
SIZE_FACTOR = 3.0
#: an edge is on a switch within this share of the switches' median spacing (the relay's
#: switch time moves with its lag and width along their ridge, a minute or two on the HVAC
#: cycle; the search's edge with what it absorbs of the path's smooth part)
WINDOW_SHARE = 0.25


class Switch(NamedTuple):
    time_s: float
    jump: float  # the signal's mean after less its mean before


class Edge(NamedTuple):
    which: int  # the transient's place in the list
    time_s: float
    jump: float


def switches(e: NDArray, rate_hz: float) -> list[Switch]:
    """The times the extension's own signal ``e`` (mean removed) changes level: a Schmitt
    trigger at ±½ of its standard deviation, each switch placed at the last crossing of its
    mean before the trigger, its jump the difference of the signal's means over the
    stretches between switches on either side."""
    e = np.asarray(e, dtype=float)
    e = e - float(np.mean(e)) if len(e) else e
    sd = float(np.std(e))
    if len(e) < 3 or not sd > 0:
        return []
    hi, lo = e > 0.5 * sd, e < -0.5 * sd
    state = 0
    idx: list[int] = []
    sign = np.signbit(e)
    for i in np.flatnonzero(hi | lo):
        s = 1 if hi[i] else -1
        if s == state:
            continue
        if state != 0:
            # the last crossing of the mean before the trigger
            j = i
            while j > 0 and sign[j - 1] == sign[i]:
                j -= 1
            idx.append(int(j))
        state = s
    if not idx:
        return []
    bounds = [0, *idx, len(e)]
    means = [float(np.mean(e[a:b])) if b > a else 0.0 for a, b in pairwise(bounds)]
    return [Switch(i / rate_hz, means[k + 1] - means[k]) for k, i in enumerate(idx)]


def edges(cands: Sequence[cz.Candidate]) -> list[Edge]:
    """The level changes of the compound search's transients: a step's, an excursion's two
    (up, then down by the same size); a warm-up or a drift has none."""
    out: list[Edge] = []
    for k, c in enumerate(cands):
        size = float(c.params.get("size", math.nan))
        if c.cause == "bias_step":
            out.append(Edge(k, float(c.params["time_s"]), size))
        elif c.cause == "excursion":
            out.append(Edge(k, float(c.params["start_s"]), size))
            out.append(Edge(k, float(c.params["end_s"]), -size))
    return out


def _matches(ed: Edge, sw: Switch) -> bool:
    return (math.copysign(1.0, ed.jump) == math.copysign(1.0, sw.jump)
            and abs(ed.jump) <= SIZE_FACTOR * abs(sw.jump)
            and abs(sw.jump) <= SIZE_FACTOR * abs(ed.jump))


def chance(ed: Edge, sws: Sequence[Switch], window_s: float, record_s: float) -> float:
    """The share of the record within ``window_s`` of a switch that matches ``ed`` (the
    same sign, a size within ``SIZE_FACTOR``): where an edge placed at random would land
    on the path's switches."""
    spans = sorted((max(0.0, s.time_s - window_s), min(record_s, s.time_s + window_s))
                   for s in sws if _matches(ed, s))
    cover, end = 0.0, 0.0
    for a, b in spans:
        a = max(a, end)
        if b > a:
            cover += b - a
            end = b
    return min(1.0, cover / record_s) if record_s > 0 else 1.0


def _tail(ps: Sequence[float], k: int) -> float:
    """P(at least ``k`` of independent events of chances ``ps``) (Poisson-binomial)."""
    if k <= 0:
        return 1.0
    dist = np.zeros(len(ps) + 1)
    dist[0] = 1.0
    for p in ps:
        dist[1:] = dist[1:] * (1 - p) + dist[:-1] * p
        dist[0] *= 1 - p
    return float(np.sum(dist[k:]))


class Lock(NamedTuple):
    own: tuple[int, ...]  # the transients whose every edge is on a switch
    on: int  # edges on a switch
    of: int  # edges
    p: float  # the chance of so many, times the θ grid's size (Bonferroni)
    window_s: float


def lock_of(cands: Sequence[cz.Candidate], sws: Sequence[Switch], record_s: float,
            n_grid: int, alpha: float = LOCK_ALPHA) -> Lock | None:
    """``locked_to_path`` on the switches ``sws`` of a record ``record_s`` long."""
    eds = edges(cands)
    if len(sws) < 2 or not eds:
        return None
    window = WINDOW_SHARE * float(np.median(np.diff([s.time_s for s in sws])))
    on: list[bool] = []
    ps: list[float] = []
    for ed in eds:
        on.append(any(abs(ed.time_s - s.time_s) <= window and _matches(ed, s) for s in sws))
        ps.append(chance(ed, sws, window, record_s))
    k = sum(on)
    p = min(1.0, max(1, n_grid) * _tail(ps, k)) if k else 1.0
    if p > alpha:
        return None
    own = tuple(j for j in range(len(cands))
                if any(ed.which == j for ed in eds)
                and all(o for ed, o in zip(eds, on, strict=True) if ed.which == j))
    return Lock(own, k, len(eds), p, window)


def locked_to_path(cands: Sequence[cz.Candidate], e: NDArray, rate_hz: float,
                   *, n_grid: int, alpha: float = LOCK_ALPHA) -> Lock | None:
    """The transients of ``cands`` that are the path's own switches, where their edges sit
    on the switches of ``e`` (the extension's own signal, the path's less its linear
    coupling) more often than chance at ``alpha``; None where they do not (or ``e`` does not
    switch). ``n_grid``: the θ (lags, widths) the path's fit chose among: its switches sit
    where the best of them put them, so the count's chance at one θ is multiplied by that
    many (Bonferroni; giving away one coincidence per fitted θ let several times the level
    through where the lag and width were fitted to the transients: the fit's best θ lines
    up more than one switch with an edge)."""
    return lock_of(cands, switches(e, rate_hz), len(e) / rate_hz, n_grid, alpha)


def grid_size(kind: str, record_s: float, rate_hz: float) -> int:
    """The θ grid points of extension ``kind`` on a record ``record_s`` long (``trials``
    over the extensions' lags the choice tries, one more for the one-lag fit's own)."""
    lags = [float(x) for x in LAG_GRID_S if x <= record_s / 8] + [1e9]
    return len(trials(kind, lags, quadratic_leads(record_s, rate_hz)))


def apart_from_path(th: ThermalFit, cands: Sequence[cz.Candidate], temps: NDArray
                    ) -> tuple[ThermalFit, list[cz.Candidate]]:
    """(``th``, the transients of ``cands`` to hold beside its path): those the path's own
    switches account for (``locked_to_path``) left out, and the path's notes saying so;
    ``th`` and every transient where its chosen extension does not switch with them."""
    pf = th.path
    if pf is None or pf.kind == "one_lag" or not cands:
        return th, list(cands)
    s = pf.chosen
    # on the log's own grid, as the path was fitted (a coarse log's 12-bit reconstruction
    # put the switches elsewhere)
    e = pf.extension_signal(temps[:, th.channel_index])
    g = grid_size(s.kind, len(e) / pf.rate_hz, pf.rate_hz)
    lock = locked_to_path(cands, e, pf.rate_hz, n_grid=g)
    if lock is None or not lock.own:
        return th, list(cands)
    names = ", ".join(sorted({cands[k].cause.replace("_", " ") for k in lock.own}))
    note = (f"{len(lock.own)} transient(s) the compound search reads on the axis as recorded "
            f"({names}) are this path's own switches: {lock.on} of their {lock.of} edges lie "
            f"within {lock.window_s:.0f} s of a switch of the path's signal of the same sign "
            f"and size, chance {lock.p:.2g} over the {g} θ of the path's grid; the path "
            "is tested beside the others only")
    pf2 = replace(pf, notes=[*pf.notes, note])
    return replace(th, path=pf2), [c for k, c in enumerate(cands) if k not in lock.own]
