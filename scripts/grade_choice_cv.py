"""Which way of choosing the grade source holds up on trips it never saw? A nested
cross-validation over all trips of the shared BMW i3 logs.

    .venv/bin/python scripts/grade_choice_cv.py --data ../shared/data

Outer loop: trip-grouped 5-fold (fold j holds out every 5th trip in name order from the
j-th). Inside each fold, on its training trips only, the grade source and the physical
candidates are chosen the two ways the closing-the-loop study offers
(``sumo_drvpw.validation.closing_the_loop_fit.GRADE_CHOICES``):

- **sequential**: the grade source from TAU_GRID_S with the calibrated terms
  (``choose_tau``), then the physical candidates on data read that way;
- **joint**: for every grade source its own physical candidates, and the source whose
  closed-loop structure cross-validates best (``joint_grade_and_physics``).

Each fold's closed-loop equation, fitted on its training trips, predicts the held-out
trips' traction energy (Σ max(P, 0)·Δt, predicted/measured − 1). The lag is 0 and the
grade comes from the accelerometer, as the tracer finds on these logs
(docs/closing-the-loop.md). Prints per-trip errors of both and their summary; run time
about 20 min on 2 cores.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from sumo_drvpw.validation import closing_the_loop_fit as F
from sumo_drvpw.validation.closing_the_loop_read import corrected_measured, load_checked, write_subset

sys.path.insert(0, str(Path(__file__).resolve().parent))
from closing_the_loop_report import _tau  # noqa: E402

K = 5


def main() -> int:
    from scipy.stats import wilcoxon

    from sumo_drvpw.data.adapters import read

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(Path(__file__).resolve().parents[2] / "shared" / "data"))
    a = ap.parse_args()
    df, rep = read("bmw-i3-tum", Path(a.data) / "bmw_i3_tum")
    roles = rep.get("roles")
    trips = sorted(df["trip_id"].unique())
    errs = {"sequential": {}, "joint": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for j in range(K):
            t0 = time.perf_counter()
            held = trips[j::K]
            train = write_subset(df, held, Path(tmp) / "train.parquet", keep=False, roles=roles)
            test = write_subset(df, held, Path(tmp) / "test.parquet", keep=True, roles=roles)
            m_train = load_checked(train, "bmw_i3")
            base_eq, _ = F.calibrate_physical(m_train, "i3_calibrated")
            line = []
            for how in errs:
                # the closed-loop equation fitted on the training trips predicts the held-out
                # trips, read with the same corrections (as scripts/closing_the_loop.py does)
                tau, _, eq, sel, r = F.grade_and_physics(train, "bmw_i3", 0.0, base_eq.terms, m_train,
                                                         "i3_closed", choice=how)
                m_held = corrected_measured(test, "bmw_i3", 0.0, True, tau["tau_s"],
                                            tau["logger_offset"]["offset_mps2"])
                e = F.regime_eval(m_held, eq, 1.0 + r)["trip_energy"]["trips"]
                errs[how].update({t: v["error"] for t, v in e.items()})
                line.append(f"{how}: {_tau(tau['tau_s'])} + [{', '.join(sel['chosen']) or 'none'}], "
                            f"grade {eq.terms['grade']:.3f}")
            print(f"fold {j + 1} ({time.perf_counter() - t0:.0f} s): " + "; ".join(line), flush=True)
    print("\ntrip        sequential   joint")
    for t in sorted(trips, key=lambda t: errs["sequential"][t]):
        print(f"{t:10s} {100 * errs['sequential'][t]:+9.1f} % {100 * errs['joint'][t]:+7.1f} %")
    for how, e in errs.items():
        a_ = 100 * np.abs(np.array(list(e.values())))
        print(f"{how}: mean abs {a_.mean():.2f} %, median {np.median(a_):.2f} %, worst {a_.max():.1f} %, "
              f"beyond 6 %: {(a_ > 6).sum()} of {len(a_)}")
    d = np.array([abs(errs["sequential"][t]) - abs(errs["joint"][t]) for t in trips])
    print(f"joint lower on {(d > 0).sum()} of {len(d)} trips; one-sided Wilcoxon p = "
          f"{wilcoxon(d, alternative='greater').pvalue:.2g}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
