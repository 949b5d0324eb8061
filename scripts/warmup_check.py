"""Does a tyre and drivetrain warm-up explain the i3's remaining per-trip errors? An
exploratory check over all trips of the shared BMW i3 logs (held-out trips included).

    .venv/bin/python scripts/warmup_check.py --data ../shared/data

Tyres (and gear oil) are cold when a trip starts and warm up over the first tens of minutes;
their rolling resistance falls as they do. The check adds to the deliverable's structure
(docs/closing-the-loop/i3_all_trips/closed_equation.toml, its terms and its ``[measurement]``)
an extra rolling force that decays with the time since the trip's start,
``[warm]*roll`` with warm = exp(−t/τ), for τ on a fixed grid, and scores each by the
trip-grouped 5-fold cross-validation the physical candidates are chosen by
(:func:`sumo_drvpw.fit.physical.trip_cv`: mean and worst abs. trip traction-energy error,
trips helped, one-sided Wilcoxon test of the per-trip abs. errors). The coefficient's
reading: the extra c_r at the start as a share of the warm c_r (``roll``). Result and
reading: docs/closing-the-loop.md ("What this shows"). About 1 min.

The logs do not say how long the car stood before a trip: a trip started minutes after the
last one starts warm, which such a term cannot see (nor a SUMO run, which knows departures
only).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy.stats import wilcoxon

EQUATION = Path(__file__).resolve().parents[1] / "docs" / "closing-the-loop" / "i3_all_trips" / "closed_equation.toml"
#: time constants of the warm-up tried [s], fixed before the run
TAU_GRID_S = (300, 600, 1200, 1800, 3600)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default="../shared/data", help="the shared data folder (holds bmw_i3_tum/)")
    a = ap.parse_args(argv)
    from sumo_drvpw.cli.import_ import write_log
    from sumo_drvpw.data.adapters import read
    from sumo_drvpw.data.log import ReadOptions
    from sumo_drvpw.data.measured import load_measured
    from sumo_drvpw.fit.physical import regime_fit, trip_cv
    from sumo_drvpw.model.equations import load_equation
    from sumo_drvpw.model.terms import term_matrix

    eq = load_equation(EQUATION)
    df, rep = read("bmw-i3-tum", Path(a.data) / "bmw_i3_tum")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "i3.parquet"
        write_log(df, {"roles": rep.get("roles")}, path)
        m = load_measured([path], eq.provenance["vehicle"], ReadOptions(measurement=eq.measurement))
    log = m.log.df
    dt, trip = log["dt_s"].to_numpy(float), log["trip_id"].astype(str).to_numpy()
    since = np.zeros(len(log))                  # time since the trip's first sample [s]
    for idx in log.groupby("trip_id", sort=False).indices.values():
        t = np.cumsum(dt[idx])
        since[idx] = t - t[0]
    x, y, use = m.inputs, m.power_w, m.usable
    terms = list(eq.terms)
    base = trip_cv(x, y, use, dt, trip, terms)
    print(f"{eq.name} ({', '.join(terms)}) on {len(base['errors'])} trips, trip-grouped 5-fold: "
          f"mean {100 * base['mean_abs_error']:.2f} %, worst {100 * base['max_abs_error']:.2f} %")
    print("| τ [s] | mean | worst | trips helped | Wilcoxon p | extra c_r at the start / c_r |")
    print("|---|---|---|---|---|---|")
    for tau in TAU_GRID_S:
        x.signals["warm"] = np.exp(-since / tau)
        cv = trip_cv(x, y, use, dt, trip, terms + ["[warm]*roll"])
        d = np.array([abs(base["errors"][t]) - abs(e) for t, e in cv["errors"].items()])
        X = term_matrix(terms + ["[warm]*roll"], x)
        ok = use & np.all(np.isfinite(X), axis=1) & np.isfinite(y)
        b, _ = regime_fit(X[ok], y[ok], False)
        print(f"| {tau} | {100 * cv['mean_abs_error']:.2f} % | {100 * cv['max_abs_error']:.2f} % | "
              f"{int((d > 0).sum())} of {len(d)} | {wilcoxon(d, alternative='greater').pvalue:.2g} | "
              f"{b[-1] / b[terms.index('roll')]:+.0%} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
