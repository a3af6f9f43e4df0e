"""``avard explain``: where the measurement leaves the fitted model, and why.

- ``engine/``        the explain pipeline on analyze's estimator and fit (run: the entry
                     points; slow: the slow view; thermal, compound, removal, channel:
                     one axis's causes, claims and refit; misfit; results);
- ``causes.py``      the time-domain causes: a warm-up transient and a bias step; the stated
                     minima of those and of a sinusoid (analyze's line finder);
- ``gauss_markov.py`` a Gauss–Markov bump in the GLS fit, and its stated minimum;
- ``thermal_fit/``   which temperature drives an axis, through what lag; compensated AVAR;
- ``thermal_paths/`` thermal paths beyond one lag, chosen by held-out likelihood;
- ``transients/``    steps, excursions and a warm-up found one after another;
- ``coupling_change.py`` whether one thermal coupling describes the record;
- ``path_switches.py`` transients that are a thermal path's own switches;
- ``holdout.py``     the gain of the extended model measured on held-out data;
- ``verdict.py``     explained or unexplained, one line an axis;
- ``report.py``      the text, JSON and figures.
"""
