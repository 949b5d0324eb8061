"""Does an idle fuel that ramps in with driving power describe the Prius Gen 2's engine at
light load better than one engine-off threshold? An exploratory check on the shared Prius
Gen-2 logs, each of its two trips held out in turn.

    .venv/bin/python scripts/idle_ramp_check.py --data ../shared/data

The engine of a power-split hybrid runs part of the time at light load (on these logs
50–60 % of the time below 10 m/s and 6 kW), so a step at one threshold cannot say how
much idle fuel a light-load step costs on average; the fuel chain's profile chooses
P_off = 0 and reads the idle fuel as implausible (docs/energy-chain-validation.md). The
check fits the charge-sustaining Willans line of ``fit/chain_fuel.py`` on the measured
driving power P_PTdrv against the SOC-corrected fuel, with its idle-fuel column replaced by
an on-share that rises linearly from 0 at P0 to 1 at P1 (P1 = P0: the step; the engine on
above a speed v_on when one is given), on a grid of (P0, P1, v_on) chosen by BIC on the
training trip, and prints, per held-out trip, the best ramp and the best step: their
parameters (idle fuel, η_m, auxiliary draw) and the held-out fuel error. Seconds.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import lsq_linear


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=Path("../shared/data"))
    args = ap.parse_args(argv)
    from sumo_drvpw.data.measured import measure
    from sumo_drvpw.fit.chain_fuel import fuel_bounds, fuel_design, fuel_grid, fuel_names
    from sumo_drvpw.validation.chain_common import read_shared

    log, veh = read_shared(args.data, "prius_gen2_torquepro", "torquepro-prius2", "prius2")
    mw, mf = measure(log, veh), measure(log, veh, "fuel")
    trips = np.asarray(log.df["trip_id"]).astype(str)
    dt = log.df["dt_s"].to_numpy(float)
    p, v, y = mw.power_w, mf.inputs.v, mf.power_w
    pb = np.nan_to_num(mf.battery_w)
    usable = mf.usable & np.isfinite(p) & np.isfinite(y)

    def share(p0, p1, von):
        s = np.clip((p - p0) / (p1 - p0), 0.0, 1.0) if p1 > p0 else (p > p0).astype(float)
        return s if von is None else np.where(v > von, 1.0, s)

    grid = [(p0, p0 + d, von) for p0 in (0.0, 1000.0, 2000.0, 3000.0, 5000.0)
            for d in (0.0, 2000.0, 4000.0, 6000.0, 10000.0, 15000.0) for von in (None, 12.0, 17.0, 20.0)]
    print("held-out trip | form | P0–P1 kW | v_on | idle kW | η_m | aux W | held-out fuel error")
    for t in dict.fromkeys(trips):
        train, test = usable & (trips != t), usable & (trips == t)
        n, w = int(train.sum()), np.sqrt(dt[train])
        rows = []
        for p0, p1, von in grid:
            s = share(p0, p1, von)
            tmpl = fuel_grid(p0, von)[0]  # the charge-sustaining line of fit/chain_fuel.py …
            x = fuel_design(tmpl, p, v, pb, [])
            x[:, 0] = s  # … its idle-fuel column the ramp: y = a·s + b·(P⁺ − P_bat) + c
            r = lsq_linear(x[train] * w[:, None], y[train] * w, bounds=fuel_bounds(fuel_names(tmpl, []))).x
            rss = float(((x[train] @ r - y[train]) ** 2 * dt[train]).sum())
            k = 3 + (p1 > p0) + (von is not None) + 1
            pred = r[0] * s + r[1] * np.maximum(p, 0.0) + r[2]  # charge-sustaining: every W of P paid
            err = float(pred[test] @ dt[test]) / float((y + r[1] * pb)[test] @ dt[test]) - 1.0
            rows.append((n * np.log(rss / n) + k * np.log(n), p0, p1, von, r, err))
        rows.sort(key=lambda z: z[0])
        for form, row in (("ramp", rows[0]), ("step", next(z for z in rows if z[2] == z[1]))):
            _, p0, p1, von, r, err = row
            print(f"{t} | {form} | {p0 / 1000:g}–{p1 / 1000:g} | {von} | {r[0] / 1000:.1f} | {1 / r[1]:.3f} | "
                  f"{r[2] / r[1]:.0f} | {err:+.1%}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
