"""The i3's battery energy per trip through the closed loop's road load, in a nested
cross-validation over all trips of the shared BMW i3 logs (issue #12's held-out figure,
with the road load of issue #11's loop instead of the fixed one of the headline pipeline).

    .venv/bin/python scripts/battery_nested_cv.py --data ../shared/data

Outer loop: the headline's trip-grouped 5-fold (fold j holds out every 5th trip in name order
from the j-th; :mod:`sumo_drvpw.validation.chain_i3`). Inside each fold, on its training trips
only:

1. the road load as the closing-the-loop study builds it
   (:mod:`sumo_drvpw.validation.closing_the_loop`): the calibrated DrvPw terms, then
   the grade source and the physical candidates chosen together (GRADE_CHOICE "joint") on
   the trip traction energy, or with ``--selection-energy net`` on the net energy;
2. the recuperation limit profiled from that equation's power against the measured motor
   power, and the battery chain (constant η, the heater's V·I and the A/C as logged loads at
   gain 1) fitted on the measured motor power of the training trips whose heater V·I is
   logged — as the headline pipeline does.

Beside it, in the same folds, the headline pipeline's own road load (I3_ROAD_TERMS on the
data read with I3_MEASUREMENT, :func:`~sumo_drvpw.validation.chain_i3.fit_road_load`) under
the same chain; its mean is checked against the committed docs/validation/summary.json.

Each chain predicts each held-out trip's battery energy from its road load's power on that
trip, read with that road load's measurement corrections. Logger dropouts are left out of
every energy, measured and predicted. Prints per held-out trip the battery error and the
road load's own net and traction motor-energy errors of both, and the summary; run time
about 16 min on 2 cores. Result and reading: docs/energy-chain.md.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from sumo_drvpw.validation import closing_the_loop_fit as F
from sumo_drvpw.validation.closing_the_loop_read import load_checked, measurement_of, write_subset

sys.path.insert(0, str(Path(__file__).resolve().parent))
from closing_the_loop_report import _tau, wheel_of  # noqa: E402

K = 5
ROOT = Path(__file__).resolve().parents[1]


def _at_wheels(eq, sel, r) -> str:
    """The closed-loop grade at the wheels (closing_the_loop_report.wheel_of), for the fold's line."""
    w = wheel_of(eq.terms, sel, r)
    return "" if w is None else f" (at the wheels {w['value']:.3f}, η {w['eta']:.3f})"


def read_as(full, meas):
    """(battery Measured, motor-power Measured, dropouts) of ``full`` read with ``meas``."""
    from sumo_drvpw.data.dropouts import log_dropouts
    from sumo_drvpw.data.log import ReadOptions
    from sumo_drvpw.data.measured import load_measured_pair

    mb, mw = load_measured_pair([full], "bmw_i3", ReadOptions(measurement=meas), "battery")
    drop = log_dropouts(mb.log)
    return mb, mw, np.zeros(len(mb.log.df), bool) if drop is None else drop


def fold_battery(mb, mw, drop, p_eq, train_ids, loads):
    """Battery power predicted on every sample from the road-load power ``p_eq`` [W] by the
    chain fitted on the logged-heater trips of ``train_ids`` (as the headline pipeline fits
    it: on the measured motor power, loads at gain 1, constant η, the recuperation limit
    profiled from ``p_eq``). Returns (predicted W, measured W with dropouts NaN, chain)."""
    from sumo_drvpw.fit.chain import calibrate_on
    from sumo_drvpw.validation.chain_i3 import fitted_recuperation_limit, with_recuperation_limit

    df = mb.log.df
    trips = df["trip_id"].to_numpy().astype(str)
    dt = df["dt_s"].to_numpy(float)
    train = np.isin(trips, sorted(train_ids))
    logged = df["heater_logged"].to_numpy(bool)
    use = mw.usable & np.isfinite(mw.inputs.theta) & train
    lim = fitted_recuperation_limit(p_eq, mw.power_w, dt, use)
    fit = calibrate_on(mb, loads=loads, mask=train & logged, p_drive_w=mw.power_w,
                       fixed={f"loads.{c}": 1.0 for c in loads}, limit=None, efficiency="constant")
    ch = with_recuperation_limit(fit.chain, lim)
    pred = ch.evaluate(p_eq, mw.inputs.v, signals=mb.inputs.signals)["power_w"]
    return pred, np.where(drop, np.nan, mb.power_w), ch


def road_errors(p_eq, mw, drop, held) -> dict:
    """Per held-out trip, the road load's own errors against the measured motor power on the
    usable samples: net (Σ P·Δt) and traction (Σ max(P, 0)·Δt) energy, predicted/measured − 1."""
    from sumo_drvpw.fit.trip_energy import trip_energy, trip_net_energy

    df = mw.log.df
    trips = df["trip_id"].to_numpy().astype(str)
    u = mw.usable & ~drop & np.isin(trips, held) & np.isfinite(p_eq)
    args = (p_eq[u], mw.power_w[u], df["dt_s"].to_numpy(float)[u], trips[u])
    net, trac = trip_net_energy(*args)["trips"], trip_energy(*args)["trips"]
    return {t: (net[t]["error"], trac[t]["error"]) for t in net}


def main() -> int:
    from scipy.stats import wilcoxon

    from sumo_drvpw.data.adapters import read
    from sumo_drvpw.validation.chain_common import trip_rows
    from sumo_drvpw.validation.chain_i3 import (I3_LOADS, I3_MEASUREMENT, I3_ROAD_TERMS, fit_road_load,
                                                with_i3_loads)

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(ROOT.parent / "shared" / "data"))
    ap.add_argument("--selection-energy", choices=F.SELECTION_ENERGIES, default=F.SELECTION_ENERGY,
                    help="the trip energy whose error chooses the closed loop's structure "
                         "(validation.closing_the_loop_fit.SELECTION_ENERGY)")
    a = ap.parse_args()
    df, rep = read("bmw-i3-tum", Path(a.data) / "bmw_i3_tum")
    df = with_i3_loads(df)
    loads = list(I3_LOADS)
    roles = dict(rep.get("roles") or {}, heater_electric_w="load", heater_logged="condition")
    trips = sorted(df["trip_id"].unique())
    how = ("closed loop", "headline")
    err = {h: {} for h in how}
    road = {h: {} for h in how}
    flagged = {}
    with tempfile.TemporaryDirectory() as tmp:
        full = write_subset(df, [], Path(tmp) / "all.parquet", keep=False, roles=roles)
        head = read_as(full, I3_MEASUREMENT)  # the headline pipeline's reading (60-s fusion)
        for j in range(K):
            t0 = time.perf_counter()
            held = trips[j::K]
            train_ids = set(trips) - set(held)
            train = write_subset(df, held, Path(tmp) / "train.parquet", keep=False, roles=roles)
            m_train = load_checked(train, "bmw_i3")
            base_eq, _ = F.calibrate_physical(m_train, "i3_calibrated")
            tau, _, eq, sel, r = F.grade_and_physics(train, "bmw_i3", 0.0, base_eq.terms, m_train,
                                                     "i3_closed", choice="joint", energy=a.selection_energy)
            del m_train
            off = tau["logger_offset"]["offset_mps2"]
            closed = read_as(full, measurement_of(full, 0.0, True, tau["tau_s"], off))
            p_closed = eq.power(closed[1].inputs)
            p_closed = np.where(p_closed < 0, (1.0 + r) * p_closed, p_closed)
            mb, mw, drop = head
            tr = mw.log.df["trip_id"].to_numpy().astype(str)
            use = mw.usable & np.isfinite(mw.inputs.theta) & np.isin(tr, sorted(train_ids))
            eq_h, _, _ = fit_road_load(mw.inputs, mw.power_w, use, I3_ROAD_TERMS, f"i3_kfold{j}")
            line = []
            for h, (mb, mw, drop), p in ((how[0], closed, p_closed), (how[1], head, eq_h.power(mw.inputs))):
                pred, meas, ch = fold_battery(mb, mw, drop, p, train_ids, loads)
                tr = mb.log.df["trip_id"].to_numpy().astype(str)
                rows = trip_rows(np.where(np.isin(tr, held), pred, np.nan), meas,
                                 mb.log.df["dt_s"].to_numpy(float), tr)
                err[h].update({x["trip"]: x["error"] for x in rows if x["trip"] in held})
                road[h].update(road_errors(p, mw, drop, held))
                line.append(f"{h}: η_t {ch.traction_efficiency:.3f}, η_r {ch.recuperation_efficiency:.3f}, "
                            f"aux {ch.aux_power_w:.0f} W, limit {ch.recuperation_limit_w or 0:.0f} W")
            logged = closed[0].log.df["heater_logged"].to_numpy(bool)
            flagged.update({t: not bool(logged[tr == t].mean() > 0.5) for t in held})
            del closed
            print(f"fold {j + 1} ({time.perf_counter() - t0:.0f} s): {_tau(tau['tau_s'])} + "
                  f"[{', '.join(sel['chosen']) or 'none'}], grade {eq.terms['grade']:.3f}{_at_wheels(eq, sel, r)}; "
                  + "; ".join(line), flush=True)
    summ = ROOT / "docs" / "validation" / "summary.json"
    if summ.exists():  # the committed headline, for a check that this script reproduces it
        rows = json.loads(summ.read_text())["energy_chain"]["bmw_i3"]["kfold"]["rows"]
        com = np.array([abs(x["error"]) for x in rows])
        print(f"committed headline (docs/validation/summary.json): mean abs {100 * com.mean():.2f} %")
    print("\nper held-out trip, battery error | road load's net | traction error (closed loop / headline)")
    for t in sorted(trips, key=lambda t: err[how[0]][t]):
        cells = [f"{100 * err[h][t]:+6.1f} %" for h in how]
        cells += [f"{100 * road[h][t][0]:+6.1f} %" for h in how]
        cells += [f"{100 * road[h][t][1]:+6.1f} %" for h in how]
        print(f"{t:9s} {cells[0]} {cells[1]} | {cells[2]} {cells[3]} | {cells[4]} {cells[5]}"
              f"   {'no heater V·I' if flagged[t] else ''}")
    f = np.array([flagged[t] for t in trips])
    e = {h: 100 * np.abs(np.array([err[h][t] for t in trips])) for h in how}
    for h in how:
        net = 100 * np.abs(np.array([road[h][t][0] for t in trips]))
        trac = 100 * np.abs(np.array([road[h][t][1] for t in trips]))
        print(f"{h}: battery mean abs {e[h].mean():.2f} % (heater V·I logged {e[h][~f].mean():.2f} %, "
              f"not logged {e[h][f].mean():.2f} %), median {np.median(e[h]):.2f} %, worst "
              f"{e[h].max():.1f} %; road load: net {net.mean():.2f} %, traction {trac.mean():.2f} %")
    d = e[how[1]] - e[how[0]]
    print(f"closed loop lower on {(d > 0).sum()} of {len(d)} trips; one-sided Wilcoxon p = "
          f"{wilcoxon(d, alternative='greater').pvalue:.2g}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
