"""One false-alarm level per axis for everything ``avard explain`` searches for.

Every cause explain may claim on an axis is a search (over lags and channels, over places
and shapes of transients, over correlation times), and an axis without any cause must come
out clean at ``ALPHA_AXIS`` for all of them together, not at each test's own level. The
level is split between the searches (Bonferroni: the chance of any false claim is at most
the sum of the shares), and each search splits its share again over its own trials:

- ``TEMPERATURE``: the thermal regression asks z ≥ 5 (``thermal_fit.Z_TEMPERATURE``) over
  about 50 correlated lag and channel trials, 50·2Φ(−5) = 2.9e-5, inside this share; where
  the coefficient's se rests on few slow octaves (its Satterthwaite dof), the two-sided t
  at this share over those trials if larger (``CouplingTest.threshold``);
- ``TRANSIENTS``: the compound search (``transients.find_compound``) at each stage, a third
  to each family (steps at ≤ 256 grid times, excursions at their pairs, warm-ups at 48 time
  constants), each family's share Bonferroni-split over its trials (``bonferroni_z``); on
  an axis with no transient only the first stage can claim falsely;
- ``DRIFT``: the time-domain likelihood ratio of a drift against a random walk, χ²(1);
- ``THERMAL_PATHS``: the extensions of the one-lag thermal model (two paths, quadratic,
  dT/dt, hysteresis, ``thermal_paths``): the extra term's jackknife z at this share
  Bonferroni-split over every grid point of every extension (``bonferroni_t``: a
  delete-a-part jackknife over G parts makes the ratio Student's t with G − 1 degrees of
  freedom, not a normal; the normal quantile let ~10× the share through);
- ``PATH_SWITCHES``: the count that gives a path's own switches the transients the
  compound search reads on them (``path_switches.locked_to_path``; a false lock leaves
  genuine transients out of the test a path must pass beside them), Bonferroni-split over
  the θ of the path's grid, each of which places the switches elsewhere;
- ``GAUSS_MARKOV``: Davies' bound on the maximum of the T scan
  (``gauss_markov.Z_GAUSS_MARKOV``; the bound at its z, 3.5e-3 at 4 kHz for 60 h, is below
  this share at every rate and length, so ``PATH_SWITCHES`` and ``SLOW_SINE_GM`` were split
  from it with no threshold moved);
- ``SLOW_SINE_GM``: the slow-sinusoid search re-run with a claimed Gauss–Markov process in
  its noise (``engine.channel._slow_sine_beside_gm``): a sinusoid it finds is explain's own
  claim, so its level is this share, not analyze's 1 %.

Bonferroni over correlated trials (adjacent step times, nearby T) is conservative: the
benchmark's null axes measure what the level really is (``python -m benchmarks
explain_weekend --rows null``; docs/explain.md). The sinusoids are analyze's line finder, at
its own 1 % per spectrum, part of the base model and not a claim of explain's (a slow
sinusoid found beside a claimed Gauss–Markov process is: ``SLOW_SINE_GM``).
"""

from __future__ import annotations

from statistics import NormalDist

from avard.core.allan.beta import t_two_sided

__all__ = ["ALPHA_AXIS", "DRIFT", "GAUSS_MARKOV", "PATH_SWITCHES", "SLOW_SINE_GM",
           "TEMPERATURE", "THERMAL_PATHS", "TRANSIENTS", "bonferroni_t", "bonferroni_z"]

TEMPERATURE = 2.5e-4
TRANSIENTS = 5e-4
DRIFT = 2.5e-4
GAUSS_MARKOV = 4.5e-3
THERMAL_PATHS = 2.5e-4
PATH_SWITCHES = 2.5e-4
SLOW_SINE_GM = 2.5e-4
#: The chance of any false claim on an axis with nothing to find (at most the shares' sum).
ALPHA_AXIS = (TEMPERATURE + TRANSIENTS + DRIFT + GAUSS_MARKOV + THERMAL_PATHS + PATH_SWITCHES
              + SLOW_SINE_GM)


def bonferroni_z(alpha: float, trials: int) -> float:
    """|z| a two-sided Gaussian statistic must reach so that the largest of ``trials`` of
    them passes by chance at most ``alpha`` of the time (Φ⁻¹(1 − α/(2·trials)))."""
    return NormalDist().inv_cdf(1.0 - alpha / (2.0 * max(1, trials)))


def bonferroni_t(alpha: float, trials: int, dof: int) -> float:
    """|t| a two-sided Student-t statistic with ``dof`` degrees of freedom (a jackknife
    ratio over dof + 1 parts) must reach so that the largest of ``trials`` of them passes by
    chance at most ``alpha`` of the time (the t quantile at α/(2·trials) per side)."""
    return t_two_sided(alpha / max(1, trials), float(dof))
