"""Allan-family estimators and their statistics.

- ``deviations.py``  batch ADEV/OADEV/MDEV/TDEV/HDEV on arrays (NIST SP 1065 equation numbers);
- ``overlapping.py`` the exact fully overlapping AVAR, streamed in bounded memory (analyze);
- ``streaming.py``   the cheap octave cascade the service keeps for 60 h in kilobytes;
- ``edf.py``, ``chi2.py`` equivalent degrees of freedom and the χ² intervals;
- ``noise_id.py``    Stable32's noise identification (lag-1 ACF, B1/R(n)), shared by every
  estimator;
- ``kernels.py``     the OADEV's inner sums: ``_kernels.c`` when built (optional), else numpy;
- ``scratch.py``     per-thread work arrays for the kernels;
- ``feed.py``        what the service's accumulators see: ``AllanFeed`` (records → blocks) and
  ``Segmenter`` (where segments end), shared with the offline replay;
- ``replay.py``      a recording replayed into them after a checkpoint (the restore).
"""
