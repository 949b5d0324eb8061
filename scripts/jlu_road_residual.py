"""Where does the JLU car's dynamometer chain miss on the road, by speed, and do two physical
readings of it hold on trips not used to fit them? An exploratory check on the shared JLU
logs (dynamometer and six road trips).

    .venv/bin/python scripts/jlu_road_residual.py --data ../shared/data

The road deliverable (docs/energy-chain/jlu_bev_road_battery.toml) closes the dyno chain
with grade and one constant auxiliary power, 969 W, where the car draws 435 W standing. The
check prints:

1. the road residual of the dyno chain (measured battery power − the chain without its
   auxiliary power, on the graded dyno road load; all six trips, usable samples) by speed
   band and by acceleration band, beside the same on the dynamometer;
2. held out (each road trip predicted from the other five), for the dyno chain with a
   constant η and with η as a speed-power map (``calibrate --efficiency speed-power`` on the
   dyno): one constant refitted as the mean residual, and the standing draw fixed at the
   measured standing battery power with a constant refitted on the moving samples only;
3. the loop closed by the battery-target tracer (:func:`sumo_drvpw.fit.chain_linear.close_loop_heldout`,
   as the deliverable's held-out figure) on both dyno chains.

Mean |error| of per-trip net battery energy (predicted/measured − 1). About 1 min.
"""

from __future__ import annotations

import argparse
import copy
import sys
from pathlib import Path

import numpy as np

SPEED_BANDS_MPS = ((0.0, 0.1), (0.1, 3.0), (3.0, 8.0), (8.0, 14.0), (14.0, 20.0), (20.0, 40.0))
ACC_BANDS_MPS2 = ((-9.0, -1.0), (-1.0, -0.3), (-0.3, 0.3), (0.3, 1.0), (1.0, 9.0))


def _bands(r, w, x, bands, use):
    return " ".join(f"[{lo:g}, {hi:g}) {np.sum((r * w)[m]) / w[m].sum():+.0f} W ({100 * w[m].sum() / w[use].sum():.0f} %)"
                    for lo, hi in bands if (m := use & (x >= lo) & (x < hi)).any())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=Path("../shared/data"))
    args = ap.parse_args(argv)
    from sumo_drvpw.data.measured import measure
    from sumo_drvpw.fit.chain import calibrate_on
    from sumo_drvpw.fit.chain_linear import close_loop_heldout
    from sumo_drvpw.model.constants import STANDSTILL_MPS
    from sumo_drvpw.model.equations import Equation, roadload_from_specs
    from sumo_drvpw.validation.chain_common import mean_abs, read_shared, trip_rows

    dlog, veh = read_shared(args.data, "jlu_bev_dyno", "jlu-dyno", "jlu_bev")
    terms = dict(roadload_from_specs(veh).terms)
    terms.pop("grade")  # the dynamometer's flat road load: the study adds the grade itself
    flat, graded = Equation("dyno", dict(terms)), Equation("dyno_grade", dict(terms, grade=1.0))
    dy = measure(dlog, veh, "battery")
    rlog, _ = read_shared(args.data, "jlu_bev_road", "jlu-road", "jlu_bev")
    ro = measure(rlog, veh, "battery")
    trips = np.asarray(rlog.df["trip_id"]).astype(str)
    dt, ddt = rlog.df["dt_s"].to_numpy(float), dlog.df["dt_s"].to_numpy(float)
    y, v, a = ro.power_w, ro.inputs.v, ro.inputs.a
    use = ro.usable & np.isfinite(y)
    stand = v < STANDSTILL_MPS
    duse = dy.usable & np.isfinite(dy.power_w)

    def per_trip(p):
        rows = trip_rows(np.where(use, p, np.nan), y, dt, trips)
        return f"{100 * mean_abs(rows):.2f} % (" + ", ".join(f"{r['trip']} {100 * r['error']:+.1f} %" for r in rows) + ")"

    for eff in ("constant", "speed-power"):
        fit = calibrate_on(dy, flat, efficiency=eff)
        bare = copy.deepcopy(fit.chain)
        bare.aux_power_w = 0.0
        pd_ = fit.chain.evaluate(flat.power(dy.inputs), dy.inputs.v, signals=dy.inputs.signals)["power_w"]
        rd = dy.power_w - bare.evaluate(flat.power(dy.inputs), dy.inputs.v, signals=dy.inputs.signals)["power_w"]
        r = y - bare.evaluate(graded.power(ro.inputs), v, signals=ro.inputs.signals)["power_w"]
        print(f"== dyno chain, efficiency {eff}: auxiliary {fit.chain.aux_power_w:.0f} W, dyno RMSE "
              f"{np.sqrt(np.mean((pd_ - dy.power_w)[duse] ** 2)):.0f} W")
        print("  residual by speed [m/s], road:", _bands(r, dt, v, SPEED_BANDS_MPS, use))
        print("  residual by speed [m/s], dyno:", _bands(rd, ddt, dy.inputs.v, SPEED_BANDS_MPS, duse))
        print("  residual by acceleration [m/s²] while moving, road:", _bands(r, dt, a, ACC_BANDS_MPS2, use & ~stand))
        one, split = np.full(y.size, np.nan), np.full(y.size, np.nan)
        for t in dict.fromkeys(trips):
            tr, ho = use & (trips != t), trips == t
            c_all = np.sum((r * dt)[tr]) / dt[tr].sum()
            c_mov = np.sum((r * dt)[tr & ~stand]) / dt[tr & ~stand].sum()
            p_st = np.sum((y * dt)[tr & stand]) / dt[tr & stand].sum()
            one[ho] = (y - r + c_all)[ho]
            split[ho] = (y - r + np.where(stand, p_st, c_mov))[ho]
            print(f"  without {t}: one constant {c_all:.0f} W; moving {c_mov:.0f} W, standing measured {p_st:.0f} W")
        print("  held out, one constant:", per_trip(one))
        print("  held out, standing measured + moving constant:", per_trip(split))
        declared = Equation("jlu_dyno_chain", dict(terms))
        declared.chain = fit.chain
        traced = close_loop_heldout(ro, declared)
        print(f"  held out, loop closed by the tracer: {100 * traced['mean_abs_error_after']:.2f} % "
              f"(found on folds: {traced['found_on']})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
