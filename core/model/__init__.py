"""The IEEE noise model and its one fit.

- ``terms.py``   the noise terms (Q, N, B, K, R, filter), their closed-form AVAR and units;
- ``fit/``       the GLS fit with the modelled covariance, presence test, intervals, upper limits.
"""
