"""``avard explain``: where the measurement leaves the fitted model, and why.

- ``engine.py``      the explain pipeline on analyze's estimator and fit;
- ``causes.py``      the time-domain causes: a warm-up transient and a bias step; the stated
                     minima of those and of a sinusoid (analyze's line finder);
- ``gauss_markov.py`` a Gauss–Markov bump in the GLS fit, and its stated minimum;
- ``thermal_fit.py`` which temperature drives an axis, through what lag; compensated AVAR;
- ``holdout.py``     the gain of the extended model measured on held-out data;
- ``report.py``      the text, JSON and figures.
"""
