"""Octave sums of the Allan differences (whole record, by part, by lag) and the covariance views
the fits read."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from avard.core.allan.deviations import (
    DEFAULT_OVERLAP,
    NORM,
    DifferenceSums,
    gram,
    grid_sums_by_part,
    segment_phase,
)
from numpy.typing import NDArray

if TYPE_CHECKING:
    pass
from avard.core.explain.thermal_fit.holes import kept_runs
from avard.core.explain.thermal_fit.settings import DS18B20_CONVERSION_S
from avard.core.explain.thermal_fit.signals import without_start


@dataclass(frozen=True)
class OctaveSums:
    """Allan difference sums at octave m of C channels over some segments: ``n`` (K,)
    differences and ``s2`` (K, C, C) = Σ D Dᵀ, on the streaming cascade's stride grid. They
    add over disjoint parts (``+``) and give the Allan covariance (``cov``)."""

    ms: NDArray[np.int64]
    n: NDArray[np.int64]
    s2: NDArray[np.float64]

    def _padded(self, k: int) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """(n, s2) with zeros for the octaves past this one's (a part shorter than 2m, or
        all inside a hole, counted no difference there)."""
        pad = k - len(self.ms)
        if pad == 0:  # the usual case: np.pad's copy was most of a jackknife scan's cost
            return self.n, self.s2
        return (np.pad(self.n, (0, pad)), np.pad(self.s2, ((0, pad), (0, 0), (0, 0))))

    def _union(self, other: OctaveSums) -> NDArray[np.int64]:
        return self.ms if len(self.ms) >= len(other.ms) else other.ms

    def __add__(self, other: OctaveSums) -> OctaveSums:
        # the octaves of the longer: truncating to the shorter let one part inside a hole
        # (no octave) or a short one drop every long τ of the whole record's sums
        ms = self._union(other)
        (n1, s1), (n2, s2) = self._padded(len(ms)), other._padded(len(ms))
        return OctaveSums(ms, n1 + n2, s1 + s2)

    def __sub__(self, other: OctaveSums) -> OctaveSums:
        ms = self._union(other)
        (n1, s1), (n2, s2) = self._padded(len(ms)), other._padded(len(ms))
        return OctaveSums(ms, n1 - n2, s1 - s2)

    def cov(self) -> NDArray[np.float64]:
        """Allan covariance (K, C, C), NaN where no difference was counted (made once: the
        lag scan reads it for every axis; read-only)."""
        if "_cov" not in self.__dict__:
            c = self._make_cov()
            c.flags.writeable = False
            object.__setattr__(self, "_cov", c)
        return self.__dict__["_cov"]  # type: ignore[no-any-return]

    def _make_cov(self) -> NDArray[np.float64]:
        scale = NORM[2] * self.ms.astype(float) ** 2 * np.maximum(self.n, 1)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where((self.n > 0)[:, None, None], self.s2 / scale[:, None, None],
                            np.nan)


def octave_sums(X: NDArray, keep: NDArray[np.bool_] | None = None, levels: int = 40,
                overlap: int = DEFAULT_OVERLAP) -> OctaveSums:
    """The difference sums ``StreamingAllan(C, rate).update`` (via ``feed(…, keep)``) holds
    after ``X`` (M, C), from the same difference kernel (``deviations.grid_sums``) on the
    same grids, without the noise identification (the lag scan needs only the covariance;
    the axis's EDF does not depend on the trial lag). A test holds it equal to the
    accumulator's covariance."""
    return octave_sums_by_part(X, np.array([0, len(X)]), keep, levels, overlap)[0]


def octave_sums_by_part(X: NDArray, edges: NDArray, keep: NDArray[np.bool_] | None = None,
                        levels: int = 40, overlap: int = DEFAULT_OVERLAP) -> list[OctaveSums]:
    """:func:`octave_sums` of ``X`` split among the contiguous parts [edges[g], edges[g+1]):
    each Allan difference of the whole record goes to the part that holds its middle, so
    the parts add up to the whole record's sums at *every* octave, and the whole minus one
    part is the record with that part's differences left out (the delete-a-group
    jackknife).

    Not the sums of each part on its own: those have no octave longer than half a part, so
    a jackknife on them fitted the lag and the coefficient on τ ≤ part/2 only (≈ 400 s on a
    4 h record, below the HVAC cycle's τ ≈ 900 s where the coupling shows most): the
    leave-one-out lags scattered twice as far as the record's own lag does and centred
    elsewhere (a faulty-log record: best lag 19 s, the ten leave-one-out lags −10…17 s)."""
    X = np.asarray(X, dtype=float)
    G = len(edges) - 1
    runs = kept_runs(len(X), keep)
    longest = max((b - a for a, b in runs), default=0)
    ms = [1 << k for k in range(levels) if 2 * (1 << k) <= longest]
    sums = [[DifferenceSums.zeros(X.shape[1]) for _ in ms] for _ in range(G)]
    for a, b in runs:
        if b - a < 2:
            continue
        p = segment_phase(X[a:b], False)
        for k, m in enumerate(ms):
            if 2 * m > b - a:
                break
            st = 1 if m <= overlap else m // overlap
            q = p[::st] if st > 1 else p
            sp = m // st
            n_d = len(q) - 2 * sp
            # difference j spans samples a + j·st … + 2m: it goes to the part of its middle
            cut = np.clip(-((a + m - np.asarray(edges, dtype=np.int64)) // st), 0, n_d)
            grid_sums_by_part(q, sp, cut, [sums[g][k] for g in range(G)])
    return [OctaveSums(np.asarray(ms, dtype=np.int64),
                       np.asarray([x.n for x in sg], dtype=np.int64),
                       np.asarray([x.s2 for x in sg], dtype=float).reshape(
                           len(ms), X.shape[1], X.shape[1])) for sg in sums]


@dataclass(frozen=True)
class AxesDifferences:
    """The axes' part of the lag scan's difference sums, the same for every trial lag: per
    octave (``ms``, stride ``st``, ``sp`` = m/st) the second differences ``d`` (n_k, C) of
    the centred axes ``centred`` (M, C), each part's (``edges``) Σ D Dᵀ ``gram`` (G, C, C)
    and its range of differences ``cuts`` (G + 1,), as ``octave_sums_by_part`` assigns them
    (:func:`lag_octave_sums`)."""

    centred: NDArray[np.float64]
    ms: list[int]
    st: list[int]
    sp: list[int]
    d: list[NDArray[np.float64]]
    cuts: list[NDArray[np.int64]]
    gram: list[NDArray[np.float64]]


def axes_differences(Y: NDArray, edges: NDArray, levels: int = 40,
                     overlap: int = DEFAULT_OVERLAP) -> AxesDifferences:
    """The axes' second differences at every octave of ``Y`` (M, C), for the parts
    [edges[g], edges[g+1]) (``[0, M]``: the whole record), once for all trial lags."""
    Yc = np.asarray(Y, dtype=float)
    Yc = Yc - Yc.mean(axis=0)
    M = len(Yc)
    ms = [1 << k for k in range(levels) if 2 * (1 << k) <= M]
    p = segment_phase(Yc, False)
    sts, sps, ds, cuts, grams = [], [], [], [], []
    e64 = np.asarray(edges, dtype=np.int64)
    for m in ms:
        st = 1 if m <= overlap else m // overlap
        q = p[::st] if st > 1 else p
        sp = m // st
        n_d = len(q) - 2 * sp
        e = q[sp:] - q[:-sp]
        d = np.ascontiguousarray(e[sp:] - e[:-sp])
        cut = np.clip(-((m - e64) // st), 0, n_d)
        sts.append(st)
        sps.append(sp)
        ds.append(d)
        cuts.append(cut)
        grams.append(np.array([gram(d[int(cut[g]):int(cut[g + 1])])
                               for g in range(len(cut) - 1)]))
    return AxesDifferences(Yc, ms, sts, sps, ds, cuts, grams)


def lag_octave_sums(axes: AxesDifferences, u: NDArray, lag_s: float, rate_hz: float
                    ) -> list[OctaveSums]:
    """``octave_sums_by_part(without_start(column_stack([Y, u]), lag_s, rate_hz), edges)``
    (no holes) from the axes' differences computed once (``axes_differences(Y, edges)``):
    the lag scan's sums with only the lagged temperature ``u`` differenced per lag.

    ``without_start`` takes from every column the mean and its multiple w of the start-up
    shape e^(−t/τ_L) (ẽ: e on its first n_e rows, 0 after); second differences drop the
    mean, so an axis's differences are D(Y) − D(ẽ)·w_Y, and its sums Σ D Dᵀ follow from the
    axes' own (``axes.gram``) by D(ẽ)'s products on its support (the first n_e rows): the
    same numbers as the general path to rounding (a test holds them together), at a quarter
    of its work for three axes. The general path stays for a record with holes (their
    settling changes the kept runs with the lag)."""
    C = axes.centred.shape[1]
    M = len(axes.centred)
    uc = without_start(np.asarray(u, dtype=float)[:, None], lag_s, rate_hz)[:, 0]
    pu = segment_phase(uc[:, None], False)[:, 0]
    # the start-up shape's phase and each axis's share of it (w_Y), as without_start has it
    w = np.zeros(C)
    pe: NDArray[np.float64] | None = None
    n_e = 0
    if lag_s != 0:
        n_e = min(M, math.ceil(37.0 * abs(lag_s) * rate_hz) + 1)
        e = np.exp(-np.arange(n_e) / (rate_hz * abs(lag_s)))
        mean_e = float(e.sum()) / M
        vv = float(np.einsum("i,i->", e, e)) - M * mean_e**2
        if vv > 0:
            w = (e @ axes.centred[:n_e]) / vv
            pe = np.empty(M + 1)
            pe[0] = 0.0
            np.cumsum(e, out=pe[1:n_e + 1])
            pe[n_e + 1:] = pe[n_e]
    G = len(axes.cuts[0]) - 1 if axes.cuts else 0
    n = np.zeros((G, len(axes.ms)), dtype=np.int64)
    s2 = np.zeros((G, len(axes.ms), C + 1, C + 1))
    # np.outer's products by broadcasting (the same multiplications, without its per-call
    # conversions: a lag scan makes this loop's few small products thousands of times)
    ww = w[:, None] * w[None, :]
    for k in range(len(axes.ms)):
        st, sp, dy, cut = axes.st[k], axes.sp[k], axes.d[k], axes.cuts[k]
        q = pu[::st] if st > 1 else pu
        eu = q[sp:] - q[:-sp]
        du = eu[sp:] - eu[:-sp]
        de: NDArray[np.float64] | None = None
        if pe is not None:
            # D(ẽ) is 0 (to the bit: its phase is constant there) from the first difference
            # that starts at or after n_e on
            ns = min(len(du), -(-n_e // st))
            qe = (pe[::st] if st > 1 else pe)[:ns + 2 * sp]
            ee = qe[sp:] - qe[:-sp]
            de = ee[sp:] - ee[:-sp]
        for g in range(G):
            j0, j1 = int(cut[g]), int(cut[g + 1])
            if j1 <= j0:
                continue
            yy = axes.gram[k][g]
            dug = du[j0:j1]
            yu = dy[j0:j1].T @ dug
            uu = float(dug @ dug)
            if de is not None and j0 < len(de):
                s1 = min(j1, len(de))
                a = dy[j0:s1].T @ de[j0:s1]
                e2 = float(de[j0:s1] @ de[j0:s1])
                yy = yy + (e2 * ww - a[:, None] * w[None, :] - w[:, None] * a[None, :])
                yy = 0.5 * (yy + yy.T)
                yu = yu - w * float(de[j0:s1] @ du[j0:s1])
            n[g, k] = j1 - j0
            s2[g, k, :C, :C] = yy
            s2[g, k, :C, C] = s2[g, k, C, :C] = yu
            s2[g, k, C, C] = uu
    ms = np.asarray(axes.ms, dtype=np.int64)
    return [OctaveSums(ms, n[g], s2[g]) for g in range(G)]


@dataclass(frozen=True)
class CovView:
    """What :func:`tempco_from_cov` reads of an Allan result (τ, covariance, EDF), from
    :class:`OctaveSums` with the axis's EDF scaled to the differences counted."""

    tau: NDArray[np.float64]
    cov: NDArray[np.float64]
    edf: NDArray[np.float64]


def covariance_block(c: NDArray[np.float64], idx: list[int]) -> NDArray[np.float64]:
    """``c[:, idx][:, :, idx]`` of a covariance stack (K, C, C) in one gather, not two: the
    same numbers in the same memory order (τ fastest), so every sum over it adds in the same
    order (the second index runs along the gathered block's first axis; the transpose has
    the plain indexing's strides: ``test_a_covariance_block_is_the_plain_indexing``)."""
    ia = np.asarray(idx, dtype=np.intp)
    return c[:, ia[None, :], ia[:, None]].transpose(0, 2, 1)


def cov_view(sums: OctaveSums, rate_hz: float, edf_ref: NDArray, n_ref: NDArray,
             cols: tuple[int, int] = (0, 1)) -> CovView:
    """The (axis, temperature) slice ``cols`` of ``sums`` with the axis's EDF ``edf_ref``
    (K,) of a reference count ``n_ref`` (K,) of differences scaled to this one's count (EDF
    is proportional to the differences for the lag's few settling blocks left out, or a
    jackknife's parts)."""
    k = min(len(sums.ms), len(edf_ref))
    cov = covariance_block(sums.cov()[:k], list(cols))
    with np.errstate(invalid="ignore", divide="ignore"):
        edf = np.asarray(edf_ref[:k], float) * sums.n[:k] / np.asarray(n_ref[:k], float)
    return CovView(sums.ms[:k] / rate_hz, cov, np.column_stack([edf, edf]))


def min_tau_for(lag_s: float, floor_s: float = 0.0) -> float:
    """The shortest τ (s) the regression uses for a trial lag: twice the DS18B20's conversion
    time, the channel's rounding floor ``floor_s`` (:func:`rounding_floor_tau`), and for a
    negative lag twice |lag|, below which the lead-lag's high-frequency gain makes the
    regressor mostly the readings' 0.0625 K rounding (an error in the variable that pulls ĉ
    towards 0: 5 % low at −60 s)."""
    base = max(2 * DS18B20_CONVERSION_S, floor_s)
    return max(base, 2.0 * -lag_s) if lag_s < 0 else base
