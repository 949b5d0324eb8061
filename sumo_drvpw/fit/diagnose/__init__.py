"""The residual tracer: find effects a declared DrvPw equation lacks, on held-out data.

Starting from a declared equation (its terms; coefficients refitted on training folds),
the tracer builds candidate effects from the log itself, scores each on held-out data,
adds the best one only when it improves held-out error significantly, refits, and
repeats until nothing significant remains.

Candidates (generated from the data, no fixed list of culprits)
----------------------------------------------------------------
For every screened extra column ``c`` of the log (numeric or boolean):

* ``[c]*v^k`` (k = 0…3; written ``[c]`` for k = 0): an additive load c·vᵏ [W per unit];
* ``[c]*TERM`` for each declared term: c changes an existing term (e.g. rolling
  resistance growing with a tyre temperature, aero with a roof-box flag);
* ``[c]^2*v^k`` (k = 0…3, not for two-valued columns): squared forms.

Plus ``v^k`` (k = 0…4) not already spanned by the model (a function of speed alone: the
seed paper's residual followed a quadratic in speed), and two per-trip effects when the
data hold ≥ 2 trips: a per-trip offset (one constant per trip, ``trip=ID``) and a
per-trip mass change (one factor per trip on the mass-bearing part of the current model,
Σ cₖ·termₖ over the terms that carry m; written to the equation as ``trip=ID*TERM``).

Column screening (leakage and junk)
-----------------------------------
A column is not offered when it (in this order): is one of the spec's measured-power
source columns (``power_w``, motor/MG1/MG2/engine torque and speed, battery voltage
and current — the target or a component of it, whichever source was used); matches
``exclude`` or misses ``include`` (glob patterns); is a position or a direction
(``POSITION_PATTERNS``: latitude, longitude, bearing, heading — where and which way the
car drove, a proxy of the road, its grade or the day's wind; offered only when ``include``
names it; a wind is estimated from the heading by ``sumo_drvpw.fit.wind``); has more than
``max_nan`` NaN among
usable samples; is constant; is id-like (monotone within every trip with > 50 %
distinct values: a clock, counter or odometer); is derived from the model inputs
(R² ≥ ``derived_r2`` of an OLS on 1, v, a, sin θ, wind — e.g. a GPS speed or an IMU
acceleration); is the same quantity as a source column under another name (|corr| ≥
``proxy_corr`` with a source column present in the log, e.g. an "executed" MG2
torque); or is a proxy of the target (|corr(c·vᵏ, P)| ≥ ``proxy_corr`` for some
k = 0…3 — a logged power, a torque, a pedal that *is* the demand). The reasons are
reported. Before that, a column whose role (``sumo_drvpw.data.roles``) is ``response`` is left
out unless ``responses`` is set.

Samples: usable samples (``sumo_drvpw.data.measured.load_measured``) with finite declared terms and
offered signals, moving at ≥ ``min_speed_mps`` (0.1 m/s): at standstill the driving
power is zero by definition of the target and every declared term vanishes, so those
samples carry no information about effects and would only penalize loads that exist
while moving.

Validation and the test
-----------------------
Samples are cut into contiguous blocks of ``block_s`` seconds within trips. With ≥ 3
trips (``validation='auto'`` or ``'trip'``) the folds are groups of whole trips (K =
min(folds, trips)); otherwise folds are blocks, interleaved within each trip (block j of
a trip goes to fold j mod K). Per-trip candidates cannot be evaluated on a trip that was
held out entirely, so they — and every candidate once a per-trip effect is in the model
— are scored on the block folds. For each fold the model (current terms + candidate) is
fitted on the other folds by OLS from per-block sufficient statistics (ZᵀZ, Zᵀy, yᵀy;
one pass over the samples per candidate) and evaluated on the held-out fold. The unit
of the test is the held-out block: d_b = SSE_b(model) − SSE_b(model + candidate). The
best candidate (smallest held-out SSE) is accepted when its one-sided p-value — twice
the smaller of a paired t-test of mean(d_b) > 0 and a Wilcoxon signed-rank test of a
positive shift of d_b (Bonferroni over the two) — times m, the number of candidates
scored in that round (Bonferroni), is < ``alpha``, **and** its relative held-out RMSE
gain 1 − √(SSE_c/SSE_0) ≥ ``min_gain``. Equal gains are ranked by candidate order, never
by rounding; before scoring, candidates identical to or spanned by earlier ones (given the
model) are dropped and listed (``details["candidates_dropped"]``).

Replication (issue #11 §4): a candidate that passes the test is kept only if it lowers the
held-out error on more than half of the trips (with ≥ 3 trips) and its energy share is
plausible (|share| ≤ 50 %); otherwise it is removed again, listed under
``details["not_replicated"]``, and the next best candidate of the round is tried. Every
finding reports ``replication``: on how many trips it helped, and per-trip RMSE before
and after.

Roles and structure: columns carry roles (:mod:`sumo_drvpw.data.roles`); responses are
offered only with ``responses`` and then labelled "response of the target — not an effect
the model lacks". Structural effects (:mod:`sumo_drvpw.fit.diagnose.structural`): a
power–speed lag is tested first and corrected in the data; recuperation regimes, air
density from altitude, a missing grade term and the accelerometer grade are candidates.

Logs of any length (issue #14): :func:`~sumo_drvpw.fit.diagnose.stream_run.diagnose_stream`
runs the same search in bounded memory — the logs are read once in batches of whole trips
(:mod:`~sumo_drvpw.fit.diagnose.source`), every statistic above is a sum gathered in a pass
over the prepared batches (:class:`~sumo_drvpw.fit.diagnose.streamed.StreamModel`), and the
block statistics are the same sums as in memory, so the report is the same to rounding
(tests/test_diagnose_stream.py). Column screening, two-valued columns, the sample interval
of the lag search and the recuperation quantiles come from the first 500,000 rows; no
figures are drawn.

Reported numbers: coefficients and their standard errors come from an OLS fit on all
analysis samples (classical standard errors; autocorrelated residuals make them
optimistic), ``p_value`` is the Bonferroni-corrected held-out test p-value; metrics
(``compare.metrics``) are on the concatenated held-out predictions; the energy share of
a term is its traction energy (Σ P_term·Δt over samples with predicted power > 0) over
the model's total traction energy; for a logged column other than a load the column is
taken about its mean over the analysis samples (a condition's zero, °C or K, is a unit's
convention: the effect is the departure from the data's conditions).
"""

from __future__ import annotations

from sumo_drvpw.fit.diagnose.candidates import Candidate, generate_candidates, screen_signals
from sumo_drvpw.fit.diagnose.options import POWER_SOURCE_COLUMNS, DiagnoseOptions
from sumo_drvpw.fit.diagnose.result import DiagnoseResult
from sumo_drvpw.fit.diagnose.search import diagnose, paired_test

__all__ = ["diagnose", "DiagnoseOptions", "DiagnoseResult", "Candidate", "screen_signals",
           "generate_candidates", "paired_test", "POWER_SOURCE_COLUMNS"]
