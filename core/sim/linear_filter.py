"""Linear recursive filters in numpy, streamed with their state: what the simulator needs of
scipy.signal (``sosfilt``, ``lfilter``, ``butter``) without loading it.

The simulated rig runs inside ``avard run --simulate``, whose resident memory budget (issue
#13, 80 MB) has no room for scipy (~40 MB). Every filter here is written in *modal* (partial
fraction) form: a transfer function with distinct poles λ_k and as many zeros as poles is

    H(z) = d + Σ_k c_k·z⁻¹ / (1 − λ_k z⁻¹)

so the output is y[j] = d·x[j] + Σ_k s_k[j−1] with one first-order recurrence per pole,
s_k[j] = λ_k·s_k[j−1] + c_k·x[j]. s_k is "what mode k adds to the next output", the same
quantity as the state of a first-order section in transposed direct form II, so a filter's
state is a few numbers per channel and carries exactly between blocks.

A first-order recurrence is evaluated without a Python loop per sample by recursive doubling
(Hillis & Steele 1986; the linear-recurrence scan of Blelloch 1990, §1.4): after the pass with
offset k every point holds the sum of its 2k newest terms, so log₂(m) vectorised passes give
the exact recurrence up to float rounding (≈ log₂(m)·ε relative, not the ε of a sequential
loop: tests/core/test_linear_filter.py holds it to scipy.signal to 1e-12). Blocks of
:data:`SCAN_BLOCK` points are scanned side by side and then joined, which keeps the number of
passes at log₂(SCAN_BLOCK) + 1 for long inputs.

Complex poles come in conjugate pairs with conjugate coefficients, so only the member with
Im λ > 0 is run, with c doubled, and the real part is taken (the pair's sum is real).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: Points scanned together before the blocks are joined (see the module docstring).
SCAN_BLOCK = 32


def _doubling(s: NDArray, lam: NDArray) -> None:
    """In place along the last axis: s[j] ← Σ_i λ^i·s[j−i] (the recurrence s[j] += λ·s[j−1]
    from s[−1] = 0), λ broadcast against s with a last axis of 1."""
    m = s.shape[-1]
    p = lam
    k = 1
    while k < m:
        s[..., k:] += p * s[..., :-k]
        p = p * p
        k *= 2


def first_order_scan(u: NDArray, lam: ArrayLike, prev: ArrayLike) -> NDArray:
    """s[j] = λ·s[j−1] + u[j] along the last axis of ``u``, from s[−1] = ``prev``.

    ``lam`` broadcasts against ``u[..., 0]`` (one λ per leading index), ``prev`` likewise.
    Returns a new array (complex when λ or u is). |λ| ≤ 1 (stable or a random walk)."""
    lam = np.asarray(lam)
    dtype = np.result_type(u, lam, prev, np.float64)
    s = np.array(u, dtype=dtype, copy=True)
    m = s.shape[-1]
    if m == 0:
        return s
    lam_b = np.broadcast_to(lam, s.shape[:-1])[..., None]
    s[..., 0] += lam_b[..., 0] * prev
    if m <= 2 * SCAN_BLOCK:
        _doubling(s, lam_b)
        return s
    nb, B = m // SCAN_BLOCK, SCAN_BLOCK
    head = nb * B
    body = s[..., :head].reshape(*s.shape[:-1], nb, B)
    _doubling(body, lam_b[..., None])
    # Each block's last point is now its own sum; the true block ends follow the same
    # recurrence with λ^B, and block b then gets λ^(i+1)·(true end of block b−1) at point i.
    ends = body[..., -1].copy()
    _doubling(ends, lam_b ** B)
    body[..., 1:, :] += ends[..., :-1, None] * (lam_b[..., None] ** np.arange(1, B + 1))
    if head < m:
        tail = s[..., head:]
        tail[..., 0] += lam_b[..., 0] * ends[..., -1]
        _doubling(tail, lam_b)
    return s


@dataclass
class ModalFilter:
    """y[j] = d·x[j] + Re Σ_k s_k[j−1], s_k[j] = λ_k s_k[j−1] + c_k x[j] (module docstring),
    over C channels, streamed: :meth:`run` carries ``state`` (C, K) between calls.

    ``lam`` (K,) the poles kept (real, or Im > 0 for a conjugate pair); ``c`` (C, K) and
    ``d`` (C,) per channel. Build with :meth:`from_zpk`."""

    lam: NDArray
    c: NDArray
    d: NDArray
    state: NDArray

    @classmethod
    def from_zpk(cls, zeros: Sequence[complex] | NDArray, poles: Sequence[complex] | NDArray,
                 gain: float, channels: int = 1) -> ModalFilter:
        """H(z) = gain·Π(1 − z_i z⁻¹)/Π(1 − λ_k z⁻¹), zeros padded at the origin to the number
        of poles; poles distinct, conjugate pairs complete. State zero."""
        zs = np.asarray(zeros, dtype=complex)
        ps = np.asarray(poles, dtype=complex)
        if len(zs) > len(ps):
            raise ValueError("more zeros than poles: the filter is not causal in this form")
        zs = np.concatenate([zs, np.zeros(len(ps) - len(zs), dtype=complex)])
        # residue of H(z) = gain·Π(z − z_i)/Π(z − λ_k) at λ_k: H − gain = Σ c_k/(z − λ_k)
        c = np.empty(len(ps), dtype=complex)
        for k, lam in enumerate(ps):
            others = np.delete(ps, k)
            if np.any(others == lam):
                raise ValueError("repeated poles have no partial-fraction form here")
            c[k] = gain * np.prod(lam - zs) / np.prod(lam - others)
        keep = ps.imag >= 0
        weight = np.where(ps.imag > 0, 2.0, 1.0)
        lam_k, c_k = ps[keep], (c * weight)[keep]
        if not np.any(lam_k.imag != 0):
            lam_k, c_k = lam_k.real.copy(), c_k.real.copy()
        cc = np.broadcast_to(c_k, (channels, len(c_k))).copy()
        return cls(lam_k, cc, np.full(channels, float(gain)),
                   np.zeros((channels, len(lam_k)), dtype=cc.dtype))

    @classmethod
    def first_order(cls, b0: float, b1: float, a: float, channels: int = 1) -> ModalFilter:
        """y[j] = a·y[j−1] + b0·x[j] + b1·x[j−1] (``lfilter([b0, b1], [1, −a])``): d = b0,
        c = b0·a + b1, written without dividing by b0 or a. State zero."""
        return cls(np.array([float(a)]), np.full((channels, 1), b0 * a + b1),
                   np.full(channels, float(b0)), np.zeros((channels, 1)))

    def steady(self, x0: ArrayLike) -> None:
        """Set the state to the steady state of a constant input ``x0`` (per channel): what
        scipy's ``sosfilt_zi``·x0 is for a cascade, so the first output is d·x0 + Σ s = H(1)·x0
        without start-up ringing."""
        x0 = np.asarray(x0, dtype=float).reshape(-1, 1)
        self.state = (self.c * x0 / (1.0 - self.lam)).astype(self.state.dtype)

    def run(self, x: NDArray) -> NDArray[np.float64]:
        """Filter ``x`` (C, m) (time along the last axis), advancing the state."""
        x = np.asarray(x, dtype=float)
        if x.shape[-1] == 0 or self.lam.size == 0:
            return self.d[:, None] * x
        s = first_order_scan(self.c[:, :, None] * x[:, None, :], self.lam[None, :],
                             self.state)
        y = self.d[:, None] * x
        y[:, 0] += self.state.sum(axis=1).real
        y[:, 1:] += s[:, :, :-1].sum(axis=1).real
        self.state = s[:, :, -1].copy()
        return y


def butterworth_lowpass_zpk(order: int, wn: float) -> tuple[NDArray, NDArray, float]:
    """Digital Butterworth low-pass (zeros, poles, gain) of corner ``wn`` (fraction of the
    Nyquist frequency, 0 < wn < 1), unit DC gain: the analog prototype's poles
    e^(jπ(2k+N+1)/(2N)) at the prewarped corner Ω = 2·tan(π·wn/2), mapped by the bilinear
    transform z = (2 + s)/(2 − s), N zeros at z = −1 (what ``scipy.signal.butter`` designs)."""
    if not 0.0 < wn < 1.0:
        raise ValueError("the corner must lie strictly between 0 and the Nyquist frequency")
    omega = 2.0 * math.tan(math.pi * wn / 2.0)
    k = np.arange(order)
    s = omega * np.exp(1j * math.pi * (2 * k + order + 1) / (2 * order))
    if order % 2:
        # the real pole of an odd order, exactly real: e^{jπ} carries 1e-16 of imaginary
        # part, which made ModalFilter count it as half of a conjugate pair (twice)
        s[order // 2] = -omega
    poles = (2.0 + s) / (2.0 - s)
    zeros = -np.ones(order, dtype=complex)
    gain = float(np.real(np.prod(1.0 - poles) / np.prod(1.0 - zeros)))
    return zeros, poles, gain
