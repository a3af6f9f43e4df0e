"""The candidates of the thermal-path choice and the settings of its search, its held-out test
and its intervals."""

from __future__ import annotations

import math

from avard.core.allan.beta import t_two_sided

CANDIDATES = ("one_lag", "two_path", "quadratic", "rate", "hysteresis")
#: What each candidate is called in a sentence.
PATH_NAMES = {"one_lag": "one lag", "two_path": "two paths", "quadratic": "a quadratic term",
              "rate": "a dT/dt term", "hysteresis": "hysteresis"}
#: Lags (s) of the grid the extensions search (besides the one-lag fit's own lag).
LAG_GRID_S = (0.0, 15.0, 30.0, 60.0, 120.0, 240.0, 480.0, 900.0, 1800.0, 3600.0)
#: Relay widths (K) of the hysteresis candidate (0.0125 K: the relay on the reconstructed
#: temperature fitted 0.025–0.045 K for a true 0.05 on 7 of 20 records, at the grid's end
#: when it began at 0.025).
WIDTHS_K = (0.0125, 0.025, 0.05, 0.1, 0.2, 0.4)
#: Negative lags (s, as their size) the hysteresis also tries: the logged sensor may lag the
#: die, and the relay's lag and width trade along a ridge (a later switch by a longer lag or
#: a wider relay) that runs through a true lag of 0 to both sides; with lags ≥ 0 only (and
#: the one-lag fit's own) the ridge was cut at 0 and the average over it (``AVERAGED``)
#: leaned to positive lags with h 9 % high (10 records of the hysteresis row); to 60 s, as
#: the lags of the ridge's flat part (ΔD ≤ 1.2 to 60 s on seed 30008), not the 120 s whose
#: 6 more relays cost the candidate 3 % more than before the leads
HYSTERESIS_LEADS_S = (15.0, 30.0, 60.0)
#: Smoothing lag (s) before the derivative (the readings' 0.0625 K steps).
RATE_SMOOTH_S = 30.0
#: Contiguous parts: the halves of the held-out choice are parts 0…4 and 5…9; the jackknife
#: leaves each out in turn.
PARTS = 10
#: t₀.₈₄(PARTS − 1): a jackknife standard error from PARTS parts has PARTS − 1 degrees of
#: freedom, so its 68 % interval is ± this many standard errors, not ± 1.
T68 = t_two_sided(0.32, PARTS - 1)
#: The jackknife z a ``LEANING`` candidate's extra term needs (``LEAN_MARGIN``): t₉ at 0.1 %
LEAN_T = t_two_sided(0.001, PARTS - 1)
#: Δ(held-out −2 ln L) an extension must win by over one lag (docs/log/explain.md: on records
#: whose truth is one lag the extensions' held-out Δ stayed above it).
HELDOUT_MARGIN = 6.0
#: Δ(−2 ln L) on the whole record within which grid points of θ count as fits as good as
#: the best for the 68 % intervals (the profile over θ): χ²₁'s 68.27 % point, the profile
#: interval on one parameter, times the best fit's Birge factor where its deviance exceeds
#: its degrees of freedom (``profile_delta``). Not the held-out choice's margin (6): as the
#: intervals' Δ it let grid points 2.4 σ from the best into every 68 % interval (two paths
#: held the truth in 33 of 34, dT/dt 15 of 16).
PROFILE_DELTA = 1.0
#: and further, for a candidate whose θ sits at the end of its grid (open): never chosen, its
#: θ is a bound the search did not close (a margin of 6 let grid-end lags of opposite sign fit
#: a typical-tempco record's slow wander)
OPEN_MARGIN = math.inf
#: The cancellation |c₁ + c₂|/max|cᵢ| under which a two-path fit of opposite signs reads as
#: the dT/dt term's limit in the note that names it (``_derivative_limit``)
DERIVATIVE_KAPPA = 0.25
#: The candidates whose predicting better, short of being chosen, makes one lag's linear
#: coefficient and lag a model's reading rather than the sensor's (``LEAN_MARGIN``): the
#: hysteresis, a response no linear path has. Not the quadratic: on 24 h typical-tempco
#: records (one true lag) it predicted better by 4.1 and 8.2 on 2 of 5, a second-order
#: reading of the room's wander, and it is chosen where it is real (its row 40/40)
LEANING = ("hysteresis",)
#: Δ(held-out −2 ln L) by which a ``LEANING`` candidate that is not chosen must still predict
#: better than one lag, its extra term's jackknife z passing a single test at 0.1 %
#: (``LEAN_T``, Student's t with ``PARTS`` − 1 dof, not the search's Bonferroni threshold),
#: for one lag's parameters to be model-dependent (no interval): a likelihood ratio of e to
#: one on data the fit did not see. On hysteresis records one lag was kept with ±4 %
#: intervals at lags of −100 to −200 s that other seeds' estimates lie outside (the
#: relay predicting better by 9.9 at z 9.3 on one of 20; with the play before, by 2.4–9.9 on
#: 11 of 17); on one-lag records (faulty log and negative lag, 10 each) the relay predicted
#: better by 2 or more on two (by 6.4 and 3.4, faulty log), at z 4.2 and 1.1
LEAN_MARGIN = 2.0
#: Most block means the fit runs on (as the lag scan).
FIT_POINTS = 1 << 14
#: The candidates whose coefficients and θ are averaged over θ's grid, each grid point
#: weighed by its likelihood (``_averaged``), not read at the best grid point: the
#: hysteresis's lag and width trade along a ridge (a later switch by a longer lag or a
#: wider relay, the same switch time at one drive amplitude) whose deviance is flat within
#: 1–2 from (0 s, 0.05 K) to (120 s, 0.0125 K), and the coefficients move along it (c
#: 0.86×, h 1.29× at (60 s, 0.025 K) on seed 30008, ΔD 0.2 below the truth's point):
#: the best grid point is noise's choice along the ridge
AVERAGED = ("hysteresis",)



#: The time constants, as multiples of a warm-up's found one, of the nuisance columns
#: e^(−t/T) that stand for it beside every candidate (``choose_path``'s ``warmups``): its
#: T was found on the one-lag residual, which a quadratic's own start bends (T 696 s for
#: 900), and a shape fixed at that T left the rest for the quadratic to take in the parts
#: it lives in (its jackknife z 7 for 26 with the T known); sums of these three follow a
#: warm-up's e^(−t/T') for T' from T/2 to 2T
WARMUP_SPAN = (0.5, 1.0, 2.0)
#: The column kinds that are nuisance beside a candidate's couplings: the lag filter's start
#: state, a warm-up found beside the coupling (``choose_path``'s ``warmups``) and the
#: signals of the transients found on the axis (``choose_path``'s ``given``)
NUISANCE = ("start", "warmup", "given")
#: The nuisance kinds that are the record's, not the path's: the path's signal fits no size
#: of theirs (``PathScore.cols`` leaves them out)
RECORD_NUISANCE = ("warmup", "given")

#: A two-path fit's own parameters (c₁, c₂ and their lags) count as resolved only when their
#: 68 % interval's half-width is within this fraction of the value (a lag: or
#: ``RESOLVED_LAG_S``), i.e. the value within ±20 % at two of its standard errors. On a drive
#: of one line the four trade along a ridge; the Fisher information of all four on the weekend
#: benchmark's records (the plate's start and the room's wander are all that add to the
#: HVAC line) puts c₂ at ±15–180 % and L2 at ±25–120 % (docs/log/explain.md), so there they are
#: "not resolved" and what is reported with intervals is the response at the drive
#: (``drive_response``), which every such record resolves to a few %.
RESOLVED_REL = 0.1
RESOLVED_LAG_S = 15.0
#: The share of the logged channel's variance in its strongest line (``drive_line``) from
#: which the drive is one line and a two-path fit's own parameters are "not resolved"
#: whatever their intervals: one complex response for four unknowns, the rest from the
#: record's start and wander, where the delete-a-part jackknife (blind to the ridge) gave
#: ±6 % to a c₁ seven times the truth (seed 30021 of the two-path row) and ±10 % to c₁ 25 %
#: off (30015), the Cramér–Rao deviation there being ±24 %. The weekend rows' HVAC-only
#: channel holds 96–98 % in its line, with the compressor 72–74 %.
ONE_LINE_SHARE = 0.9
