"""Can a battery's energy counters stand in for its V·I? A check on the shared JLU road trips,
which log both: the battery's voltage and current at 20 Hz, and the BMS's cumulative
counters of discharged and charged energy (tot_disc, tot_char; kWh in steps of 0.002).

    .venv/bin/python scripts/jlu_counters.py --data ../shared/data

Prints, per road trip:

1. the energy each counter books against the terminal V·I (discharged: Σ max(V·I, 0)·Δt;
   charged: Σ max(−V·I, 0)·Δt), and the pack resistance R that would make the difference
   I²R (a count at the cells' open-circuit voltage books V·I + I²R on discharge and
   V·I − I²R on charge: both readings of R should then agree), and over all trips together
   the least-squares R against the other reading of such differences, an offset of the
   counter's current (it books V·ΔI·t more on discharge and less on charge);
2. the battery power the reader derives from the counters alone
   (:mod:`sumo_drvpw.data.counters`): its net and traction energy against V·I's, its
   correlation with V·I over 1-s means, and the lag that best aligns it with V·I;
3. the loop closed from the dynamometer chain by the battery-target tracer, leave-one-trip-out
   (:func:`sumo_drvpw.fit.chain_linear.close_loop_heldout`, as docs/energy-chain-validation.md's
   road figure), once on V·I and once on the counters alone (V·I dropped from the road logs):
   each held-out trip's predicted net energy against the V·I-measured one;
4. the chain calibrated on all six trips (the published road load with grade, no
   recuperation limit) on V·I, on the counters, and on the V·I integrated into counters of
   the car's 2-Wh step — read as this car's are (once a second: rises of several steps at
   once are common) and as a counter that reports each step when crossed — so what the
   counters' step and cadence do to the parameters is told apart from what they count.

About 1 min.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

KWH = 3.6e6


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=Path("../shared/data"))
    args = ap.parse_args(argv)
    from sumo_drvpw.data.counters import COUNTERS
    from sumo_drvpw.data.log import from_frame
    from sumo_drvpw.data.measured import measure
    from sumo_drvpw.data.powertrain import measured_battery_power
    from sumo_drvpw.fit.chain import calibrate_on
    from sumo_drvpw.fit.chain_linear import close_loop_heldout
    from sumo_drvpw.model.equations import Equation, roadload_from_specs
    from sumo_drvpw.validation.chain_common import read_shared
    from sumo_drvpw.data import adapters

    dlog, veh = read_shared(args.data, "jlu_bev_dyno", "jlu-dyno", "jlu_bev")
    df, _ = adapters.read("jlu-road", args.data / "jlu_bev_road")
    vi_log = from_frame(df, veh, name="jlu_bev_road")
    ctr_log = from_frame(df.drop(columns=["battery_voltage_v", "battery_current_a"]), veh, name="jlu_bev_road (counters)")
    p_vi, _ = measured_battery_power(vi_log, veh)
    p_ctr, src = measured_battery_power(ctr_log, veh)
    print(f"battery power from the counters alone: {src}")
    trips = df["trip_id"].astype(str).to_numpy()
    dt = vi_log.df["dt_s"].to_numpy(float)
    i_a = df["battery_current_a"].to_numpy(float)

    print("\n1. counters against the terminal V·I (kWh; R from discharge / charge, mΩ)")
    a_rows, diffs = [], []
    for t in dict.fromkeys(trips):
        s = trips == t
        d, c = (df.loc[s, k].to_numpy(float) for k in COUNTERS)
        ed, ec = (d[-1] - d[0]) / KWH, (c[-1] - c[0]) / KWH
        p, w, i = p_vi[s], dt[s], i_a[s]
        vd, vc = float(np.clip(p, 0, None) @ w) / KWH, float(np.clip(-p, 0, None) @ w) / KWH
        i2d, i2c = float((i ** 2 * (p > 0)) @ w), float((i ** 2 * (p < 0)) @ w)
        v = df.loc[s, "battery_voltage_v"].to_numpy(float)
        a_rows += [[i2d, float((v * (p > 0)) @ w)], [i2c, float((v * (p < 0)) @ w)]]
        diffs += [(ed - vd) * KWH, (vc - ec) * KWH]
        print(f"  {t}: discharged {ed:.3f} vs {vd:.3f} ({100 * (ed / vd - 1):+.1f} %), charged {ec:.3f} vs {vc:.3f} "
              f"({100 * (ec / vc - 1):+.1f} %); R {1e3 * (ed - vd) * KWH / i2d:.0f} / {1e3 * (vc - ec) * KWH / i2c:.0f}")

    a, y = np.asarray(a_rows), np.asarray(diffs)
    for k, how, unit, f in ((0, "pack resistance R (I²R)", "mΩ", 1e3), (1, "current offset ΔI", "A", 1.0)):
        x = float(np.linalg.lstsq(a[:, [k]], y, rcond=None)[0][0])
        print(f"  all trips, {how}: {f * x:.3g} {unit}, rms misfit {np.sqrt(np.mean((y - a[:, k] * x) ** 2)) / 1e3:.0f} kJ "
              f"(a counter step: {2 * 3.6:.1f} kJ)")

    print("\n2. the battery power derived from the counters against V·I")
    for t in dict.fromkeys(trips):
        s = trips == t
        a, b, w = p_vi[s], p_ctr[s], dt[s]
        n = len(a) // 20 * 20
        r = np.corrcoef(a[:n].reshape(-1, 20).mean(1), b[:n].reshape(-1, 20).mean(1))[0, 1]
        x, y = a - a.mean(), b - b.mean()
        lags = np.arange(-40, 41)
        cc = [x[max(0, -k):len(x) - max(0, k)] @ y[max(0, k):len(y) - max(0, -k)] for k in lags]
        lag = float(lags[int(np.argmax(cc))] * np.median(np.diff(vi_log.df["time_s"].to_numpy(float)[s])))
        print(f"  {t}: net {float(b @ w) / KWH:.3f} vs {float(a @ w) / KWH:.3f} kWh "
              f"({100 * (float(b @ w) / float(a @ w) - 1):+.1f} %), traction {float(np.clip(b, 0, None) @ w) / KWH:.3f} vs "
              f"{float(np.clip(a, 0, None) @ w) / KWH:.3f} ({100 * (float(np.clip(b, 0, None) @ w) / float(np.clip(a, 0, None) @ w) - 1):+.1f} %); "
              f"r (1-s means) {r:.3f}; counter power later by {lag:+.2f} s")

    print("\n3. the loop closed from the dynamometer chain, leave-one-trip-out; held-out net energy against V·I")
    terms = dict(roadload_from_specs(veh).terms)
    terms.pop("grade")  # the dynamometer's flat road load: the study adds the grade itself
    dfit = calibrate_on(measure(dlog, veh, "battery"), Equation("dyno", dict(terms)))
    declared = Equation("jlu_dyno_chain", dict(terms))
    declared.chain = dfit.chain
    for name, log in (("V·I", vi_log), ("counters alone", ctr_log)):
        m = measure(log, veh, "battery")
        res = close_loop_heldout(m, declared)
        errs = []
        for t, r in res["trips"].items():
            use = (trips == t) & m.usable & np.isfinite(m.power_w)
            e_vi = float((p_vi * dt)[use].sum())
            errs.append(r["after_j"] / e_vi - 1)
        found = ", ".join(f"{k} ({v} of {len(res['trips'])})" for k, v in res["found_on"].items())
        print(f"  target {name}: mean |error| {100 * np.mean(np.abs(errs)):.1f} % (per trip "
              + ", ".join(f"{t} {100 * e:+.1f} %" for t, e in zip(res["trips"], errs))
              + f"); against its own target {100 * res['mean_abs_error_after']:.1f} %; found: {found}")
    print("\n4. the chain on all six trips (graded road load, no limit): η_t, η_r, auxiliary W")
    graded = Equation("dyno_grade", dict(terms, grade=1.0))
    for name, d in (("V·I", df), ("counters", df.drop(columns=["battery_voltage_v", "battery_current_a"])),
                    ("V·I into 2-Wh counters read once a second", _quantised(df, 1.0)),
                    ("V·I into 2-Wh counters read as crossed", _quantised(df, None))):
        f = calibrate_on(measure(from_frame(d, veh, name=name), veh, "battery"), graded, limit=None)
        v = {k: p["value"] for k, p in f.parameters.items()}
        print(f"  {name}: {v['traction_efficiency']:.3f}, {v['recuperation_efficiency']:.3f}, "
              f"{v['aux_power_w']:.0f} W (R² {f.r2:.3f})")
    return 0


def _quantised(df, every_s, step_j=7200.0):
    """The road logs with V·I replaced by counters of ``step_j`` integrated from it, read every
    ``every_s`` seconds (held between readings) or, None, at every sample."""
    import pandas as pd

    from sumo_drvpw.data.counters import COUNTERS

    from sumo_drvpw.synth.effects import energy_counters

    out = []
    for _, g in df.groupby("trip_id", sort=False):
        p = (g["battery_voltage_v"] * g["battery_current_a"]).to_numpy(float)
        t = g["time_s"].to_numpy(float)
        e_d, e_c = energy_counters(t, p, step_j)
        if every_s:  # read once every every_s: each reading held to the next
            k = np.floor((t - t[0]) / every_s)
            idx = np.maximum.accumulate(np.where(np.r_[True, k[1:] != k[:-1]], np.arange(len(t)), 0))
            e_d, e_c = e_d[idx], e_c[idx]
        out.append(g.assign(**{COUNTERS[0]: e_d, COUNTERS[1]: e_c}))
    return pd.concat(out).drop(columns=["battery_voltage_v", "battery_current_a"])


if __name__ == "__main__":
    sys.exit(main())
