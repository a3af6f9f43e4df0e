"""The model's components (IEEE 952 Annex C closed forms, the filtered white and flicker curves, a
sinusoid, a Gauss–Markov process) and the covariance of AVAR estimates under them (Greenhall
and Riley's finite-record variances)."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from functools import lru_cache

import numpy as np
from avard.core.allan.edf import edf_greenhall
from avard.core.errors import FitError
from avard.core.model import terms as mdl
from avard.core.model.fit.problem import _avar_cov, _Problem
from avard.core.model.fit.results import _VALUE_KEYS, Component
from avard.core.model.terms import TERMS, UNITS
from numpy.typing import ArrayLike, NDArray


def _components(terms: Iterable[str], extra: Sequence[Mapping], filter_corner_hz: float | None,
                rate_hz: float) -> list[Component]:
    comps = []
    for t in terms:
        if t not in TERMS:
            raise FitError(f"unknown noise term {t!r}; choose from {', '.join(TERMS)}")
        if t == "velocity_random_walk" and filter_corner_hz is not None:
            comps.append(Component(t, "filter", {"corner_hz": float(filter_corner_hz)}, "N",
                                   UNITS[t]))
        elif t == "bias_instability" and filter_corner_hz is not None:
            comps.append(Component(t, "lowpass_flicker", {"corner_hz": float(filter_corner_hz)},
                                   "value", UNITS[t]))
        else:
            comps.append(Component(t, t, {}, "value", UNITS[t]))
    for e in extra:
        cause = e.get("cause")
        if cause not in _VALUE_KEYS:
            raise FitError(f"extra component {e!r}: cause must be one of {sorted(_VALUE_KEYS)}")
        key, unit = _VALUE_KEYS[cause]
        params = {k: float(v) for k, v in dict(e.get("params", {})).items()}
        fixed = params.pop(key, None)
        if cause == "sinusoid":
            f0 = params.get("frequency_hz")
            if f0 is None or not 0 < f0 <= rate_hz / 2:
                raise FitError(f"sinusoid needs 0 < frequency_hz <= {rate_hz / 2} Hz; got {f0}")
            label = f"sinusoid {f0:.6g} Hz"
        elif cause == "white":
            label = str(e.get("label", "white"))
        elif cause == "gauss_markov":
            if "time_constant_s" in params:  # the explain pipeline's name for T
                params["T"] = params.pop("time_constant_s")
            if params.get("T", 0) <= 0:
                raise FitError("gauss_markov needs a correlation time T > 0 s in params")
            label = f"gauss_markov T={params['T']:.4g} s"
        else:
            if "corner_hz" not in params:
                raise FitError("filter needs params corner_hz")
            label = "filtered white"
        comps.append(Component(label, cause, params, key, unit, fixed))
    return comps


def model_components(terms: Iterable[str], extra: Sequence[Mapping] = (), *, rate_hz: float,
                     filter_corner_hz: float | None = None) -> list[Component]:
    """The components ``fit_noise`` builds for ``terms`` and ``extra`` (same arguments), for
    computing with the fit's own model outside a fit (e.g. a stated detection minimum)."""
    return _components(terms, extra, filter_corner_hz, rate_hz)


#: The power-law type (α of S_y ∝ f^α) of each noise cause, for its Greenhall–Riley EDF;
#: a cause not listed (a Gauss–Markov process, which is no one power law) keeps Whittle's.
CAUSE_ALPHA = {"quantization": 2, "velocity_random_walk": 0, "white": 0, "filter": 0,
                "lowpass_white": 0, "bias_instability": -1, "lowpass_flicker": -1,
                "rate_random_walk": -2}


def _covariance_kernels(components: Sequence[Component], m: NDArray[np.int64],
                        stride: NDArray, M: NDArray[np.float64], rate_hz: float
                        ) -> NDArray[np.float64]:
    """The kernels of ``mdl.avar_covariance_kernels`` with each component's variance at
    each τ made Greenhall and Riley's finite-record value (NIST SP 1065 §5.3), correlations
    kept. Whittle's (2/M)∫S²|H|⁴ is first order in 1/M: with few averages it understates
    the variance of a flicker or random-walk estimate (by 12 % at 13 averages of 60 h), and
    the fit's χ² test rejected 3.0 % of pure white + flicker 60 h records at its 1 % level
    (issue 24). G[k, l, a, b] is scaled by (g_ka g_kb g_la g_lb)^¼, g_ka = GR's variance of
    component a alone at τ_k over Whittle's, so each pure component's diagonal is GR's."""
    G = mdl.avar_covariance_kernels(m, [c.psd(rate_hz) for c in components])
    K, A = len(m), len(components)
    g = np.ones((K, A))
    # the strides as the loop reads them (int() of each, as astype truncates)
    on = (np.asarray(m, dtype=np.int64).tobytes(), np.asarray(stride).astype(np.int64).tobytes(),
          np.asarray(M, dtype=np.float64).tobytes(), float(rate_hz))
    for a, comp in enumerate(components):
        alpha = CAUSE_ALPHA.get(comp.cause)
        if alpha is None:
            continue
        g[:, a] = _gr_scale(comp.cause, comp.value_key, tuple(sorted(comp.params.items())),
                            alpha, np.ascontiguousarray(G[:, :, a, a].diagonal()).tobytes(),
                            *on)
    r = np.sqrt(np.sqrt(g))  # (K, A): g^¼
    return G * (r[:, None, :, None] * r[:, None, None, :] * r[None, :, :, None]
                * r[None, :, None, :])


@lru_cache(maxsize=1024)
def _gr_scale(cause: str, value_key: str, params: tuple[tuple[str, float], ...], alpha: int,
              diag: bytes, m: bytes, stride: bytes, M: bytes, rate_hz: float
              ) -> NDArray[np.float64]:
    """Whittle's variance of one component alone at each τ over Greenhall and Riley's
    (``_covariance_kernels``' g), from its kernels' diagonal ``diag`` and the τ (``m``,
    ``stride``, ``M``: the arrays' bytes): a pure function of them, the same for every fit on
    these τ (a Gauss–Markov scan fits once per correlation time, every other component
    unchanged), so computed once (read-only)."""
    mk = np.frombuffer(m, dtype=np.int64)
    st = np.frombuffer(stride, dtype=np.int64)
    Mk = np.frombuffer(M, dtype=np.float64)
    d = np.frombuffer(diag, dtype=np.float64)
    b = Component(cause, cause, dict(params), value_key, "").basis(mk / rate_hz, rate_hz)
    out = np.ones(len(mk))
    for k in range(len(mk)):
        if d[k] <= 0 or not b[k] > 0:
            continue
        whittle = b[k] ** 2 * Mk[k] / d[k]
        gr = edf_greenhall(alpha, 2, int(mk[k]), max(int(st[k]), 1), int(Mk[k]) + 1)
        if math.isfinite(gr) and gr > 0:
            out[k] = whittle / gr
    out.setflags(write=False)
    return out


def avar_estimate_covariance(components: Sequence[Component], theta: ArrayLike,
                             m: ArrayLike, n_samples: ArrayLike, rate_hz: float,
                             stride: ArrayLike | None = None) -> NDArray[np.float64]:
    """Cov(σ̂²_k, σ̂²_l) of overlapping AVAR estimates at τ_k = m_k/fs from records of
    ``n_samples`` samples, for the model Σθ_j·b_j: the covariance ``fit_noise`` weights its
    fit with (Whittle kernels (2/M)∫S²|H_k|²|H_l|²dν of the components' spectra, each
    power law's variance made Greenhall–Riley's: ``_covariance_kernels``; the NIST SP 1065
    §5.3 floor 2σ⁴/EDF on the diagonal). ``theta`` in the order of ``components``;
    ``stride`` the samples between the differences of each τ (1, fully overlapping, by
    default)."""
    m_a = np.asarray(m, dtype=np.int64)
    M = np.asarray(n_samples, dtype=float) * np.ones(len(m_a))
    tau = m_a / float(rate_hz)
    th = np.asarray(theta, dtype=float)
    X = np.column_stack([c.basis(tau, rate_hz) for c in components])
    st = np.ones(len(m_a)) if stride is None else np.asarray(stride) * np.ones(len(m_a))
    G = _covariance_kernels(components, m_a, st, M, float(rate_hz))
    p = _Problem(y=X @ th, X=X, fixed=np.zeros(len(m_a)), G=G, theta_fixed=np.zeros(0), M=M,
                 edf_floor=100.0 * M, m_tau=tau)
    return _avar_cov(p, th, np.arange(len(m_a)))
