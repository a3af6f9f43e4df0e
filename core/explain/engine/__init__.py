"""``avard explain``: where the fitted noise model leaves the measurement, the physical cause,
and the model extended by it; on the engine of ``avard analyze``. docs/explain.md is the
reference.

Streamed, in bounded memory:

1. **Base model = analyze's fit.** ``explain_file`` calls ``analysis.engine.analyze`` on the
   record, the very function ``avard analyze`` runs, with its passes and so its peak memory
   (blocks from anywhere, ``explain_stream``, go through the same ``analyze`` in one pass);
   the record is screened once (``core.io.screen.ScreenedSource``) for both. Its Allan
   estimator and EDF, its line finder (``analysis.spectrum.find_lines``), its
   ``fit.fit_noise`` GLS with the modelled covariance, presence test, intervals and upper
   limits. Sinusoids found there are part of the base model.
2. **Slow view.** On analyze's first pass (``analysis.engine.FirstPassTap``: that pass reads
   every column and the temperatures through the one screen; only a parallel analysis, whose
   workers read the chunks, leaves it to one more read), block means of every axis and
   temperature channel are kept (blocks of 2^k samples, at least ``BLOCK_S``, at most
   ``MAX_POINTS`` per channel: ≈ 2 MB a channel).
   Everything explain adds acts on seconds or longer, so it is found there.
3. **Causes**, each tested at its share of one false-alarm level per axis (``alarm``):

   - ``temperature`` (:mod:`avard.core.explain.thermal_fit`, then
     :mod:`avard.core.explain.thermal_paths`): which logged channel drives the axis through a
     first-order lag of either sign, coefficient (m/s²/K) and lag (s) with 68 % intervals from
     the streaming Allan covariance of axis and lagged temperature; then whether a richer path
     (two lags, a quadratic, a dT/dt term, hysteresis) predicts held-out halves better.
   - ``warmup``, ``bias_step``, ``excursion`` and ``drift``
     (:mod:`avard.core.explain.transients`, ``compound``): on the slow view by GLS with the
     noise covariance of N, B, K; ``find_compound`` proposes effects one at a time while the
     best reaches a fraction of its Bonferroni threshold, refines them together and drops,
     one at a time, those below their threshold in the joint fit against the noise with all
     of them removed; ``confirm_compound`` is the claim's test (z on the scan's grid and the
     size's distance from zero, both at the threshold), at the search's end and again when a
     transient is taken out afterwards (below the temperature's rounding through the coupling,
     ``causes.transient_floor``; in a hole of the driving log, ``_not_in_hole``; a warm-up
     the lag filter's start state can make). A drift is told from a random walk in the time
     domain (``transients.test_drift``). The window-contrast detectors of
     :mod:`avard.core.explain.causes` serve only quick looks (the thermal start state's
     check, a held-out part's leftover step).
   - ``gauss_markov`` (:mod:`avard.core.explain.gauss_markov`): a component of the GLS fit
     itself (closed-form AVAR), its T scanned by −2 ln L.
   - ``sinusoid`` / ``periodic``: analyze's lines, one finding per disturbance
     (``spectrum.line_groups``).

   The claimed signals are removed from the axis through the Allan covariance of axis and
   signal (``removed_avar``) and analyze's fit is made again on what is left, their
   parameters' uncertainty carried in as a covariance of the points
   (``removal_covariance``, ``fit_noise(added_cov=…)``). Rate ramp, the chip filter and the
   LSB rounding are terms of analyze's model already.
4. **Gain**: generalised χ²/dof (with the modelled covariance) of the base over the extended
   fit: 1 = no change. **Verdict** (:mod:`avard.core.explain.verdict`): whether the extended
   model describes the axis in-sample and on held-out data, else "unexplained".
5. **Held-out gain** (:mod:`avard.core.explain.holdout`): both models refitted on one half of the
   slow view predict the other (two folds), or, with a second record of the same sensor
   (``holdout``), fitted on this record predict that one; 1 − χ²_ext/χ²_base of the held-out
   AVAR.
"""

from __future__ import annotations

from avard.core.explain.causes import Finding
from avard.core.explain.engine.misfit import misfit_ranges
from avard.core.explain.engine.results import ChannelExplanation, Explanation
from avard.core.explain.engine.run import explain_file, explain_stream
from avard.core.explain.engine.slow import SlowView, block_size

__all__ = ["ChannelExplanation", "Explanation", "Finding", "SlowView", "block_size",
           "explain_file", "explain_stream", "misfit_ranges"]
