"""core/model/bounded.py against scipy.optimize.minimize_scalar(method="bounded"), whose
steps it follows: the same minimum to the last bit, on smooth, flat, multimodal and
boundary-seeking functions, with the options the Gauss–Markov scan uses and scipy's own."""

from __future__ import annotations

import math

import numpy as np
import pytest
from avard.core.model.bounded import minimize_bounded

scipy_optimize = pytest.importorskip("scipy.optimize")

FUNCS = {
    "parabola": lambda x: (x - 0.3) ** 2,
    "quartic_flat": lambda x: (x - 1.7) ** 4,
    "cosine": lambda x: math.cos(3.0 * x) + 0.1 * x,
    "to_the_left_end": lambda x: x,
    "to_the_right_end": lambda x: -x,
    "constant": lambda x: 1.0,
    "kink": lambda x: abs(x - 0.123456),
    "huge_outside": lambda x: 1e300 if x > 1.0 else (x - 0.9) ** 2,
}


@pytest.mark.parametrize("name", sorted(FUNCS))
@pytest.mark.parametrize("opts", [{"xatol": 0.01, "maxiter": 25}, {"xatol": 1e-5, "maxiter": 500},
                                  {"xatol": 1e-9, "maxiter": 4}])
def test_the_same_minimum_as_scipy_to_the_last_bit(name: str, opts: dict) -> None:
    f = FUNCS[name]
    for a, b in ((-1.0, 2.0), (0.5, 0.7), (math.log(4.0), math.log(900.0))):
        calls: list[float] = []
        theirs_calls: list[float] = []

        def traced(x: float, seen: list[float] = calls) -> float:
            seen.append(float(x))
            return f(float(x))

        def theirs_traced(x: float, seen: list[float] = theirs_calls) -> float:
            seen.append(float(x))
            return f(float(x))

        mine = minimize_bounded(traced, a, b, **opts)
        theirs = scipy_optimize.minimize_scalar(theirs_traced, bounds=(a, b),
                                                method="bounded", options=opts)
        assert calls == theirs_calls  # the same trial points, in the same order
        assert mine.x == float(theirs.x) and mine.fun == float(theirs.fun)
        assert mine.nfev == theirs.nfev
        assert mine.converged == bool(theirs.success)
        assert a <= mine.x <= b


def test_bad_bounds_are_refused() -> None:
    with pytest.raises(ValueError, match="lower bound"):
        minimize_bounded(abs, 1.0, 0.0)
    with pytest.raises(ValueError, match="finite"):
        minimize_bounded(abs, 0.0, np.inf)
