"""A Gauss–Markov process must not raise the floor that hides a transient (issue 23 item 3,
across cause families; adv29 D8): once a process is claimed on an axis, the transient search
runs again with it in its noise. Records made here with numpy (white noise, a first-order
Gauss–Markov process as an exact AR(1), a bias step), apart from adversary_gen4's."""

from __future__ import annotations

import math

import numpy as np
import pytest
from avard.core.explain.engine import explain_file
from avard.core.explain.options import ExplainOptions
from avard.core.explain.transients import robust_noise
from avard.core.io.source import open_record

RATE = 10.0
N_WHITE = 1.5e-4   # m/s/√s


def _gm(n: int, sigma: float, T: float, rng: np.random.Generator) -> np.ndarray:
    a = math.exp(-1.0 / (RATE * T))
    w = rng.standard_normal(n) * sigma * math.sqrt(1.0 - a * a)
    x = np.empty(n)
    acc = rng.standard_normal() * sigma
    for i in range(n):
        acc = a * acc + w[i]
        x[i] = acc
    return x


def _record(tmp_path, seed: int, step: float, hours: float = 4.0, sigma: float = 1.8e-4,
            T: float = 25.0):
    rng = np.random.default_rng(seed)
    n = round(hours * 3600 * RATE)
    acc = rng.standard_normal((n, 2)) * N_WHITE * math.sqrt(RATE)
    acc[:, 0] += _gm(n, sigma, T, rng)
    at = int(0.6 * n)
    acc[at:, 0] += step
    path = tmp_path / f"gm_{seed}_{step:g}.npz"
    np.savez(path, accel=acc, rate_hz=np.float64(RATE))
    return path, at / RATE


def _x(path):
    d = explain_file(open_record(path), ExplainOptions(channels=("ch0",))).to_dict()
    return d["channels"]["ch0"]


def test_robust_noise_reads_a_gauss_markov_bump_as_one_when_its_time_constant_is_given():
    rng = np.random.default_rng(5)
    rate_b = 0.625                      # the slow view's blocks of 16 samples at 10 Hz
    n = round(4 * 3600 * RATE)
    x = rng.standard_normal(n) * N_WHITE * math.sqrt(RATE) + _gm(n, 1.2e-4, 60.0, rng)
    y = x.reshape(-1, 16).mean(axis=1)
    with_gm = robust_noise(y, rate_b, N_WHITE, gm_T=60.0)
    assert with_gm["GM_T"] == 60.0
    assert abs(with_gm["GM_sigma"] / 1.2e-4 - 1) < 0.2, with_gm
    # without it the bump is flicker or random walk, well above what the truth (zero) allows
    without = robust_noise(y, rate_b, N_WHITE)
    assert "GM_sigma" not in without
    assert without["B"] > 2 * with_gm["B"] or without["K"] > 2 * with_gm["K"], (without, with_gm)


@pytest.mark.parametrize("seed", [11, 12])
def test_a_step_beside_a_gauss_markov_process_is_claimed(tmp_path, seed):
    path, t_step = _record(tmp_path, seed, step=9e-4)
    ch = _x(path)
    claimed = {f["cause"]: f for f in ch["findings"] if f["claimed"]}
    assert "gauss_markov" in claimed, ch["verdict"]["line"]
    assert "bias_step" in claimed, [f["evidence"] for f in ch["findings"]
                                    if f["cause"] == "bias_step"]
    s = claimed["bias_step"]
    assert abs(s["params"]["size"] / 9e-4 - 1) < 0.2, s["params"]
    assert abs(s["params"]["time_s"] - t_step) < 60.0, s["params"]
    # the step out, nothing is left for a random walk to be made of
    assert not ch["extended"]["terms"]["rate_random_walk"]["present"]


def test_a_gauss_markov_process_alone_gets_no_transient(tmp_path):
    path, _ = _record(tmp_path, 13, step=0.0)
    ch = _x(path)
    claimed = [f["cause"] for f in ch["findings"] if f["claimed"]]
    assert "gauss_markov" in claimed
    assert not set(claimed) & {"bias_step", "excursion", "warmup", "drift"}, claimed
