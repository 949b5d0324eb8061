"""Does the petrol Willans line want more than one intercept? An exploratory check on the
EPA Test Car List of the shared data, prompted by Argonne's D3 Camry tests
(docs/d3-camry.md: calibrated without its highway test, the chain booked the highway
12.6 % high; its standing fuel and its intercept in gear differ, and 10–21 % of its moving
time ran without fuel).

    .venv/bin/python scripts/fleet_intercept_check.py --data ../shared/data

Per certification test of every conventional petrol configuration (docs/epa-fleet.md's
selection, wheel power and fit: WLS with weights 1/E_fuel², each car's own road load), the
fleet line E_fuel = p·D·T + E⁺/η against structures with the intercept split: standing
and moving time apart, or no fuel while moving with the wheel power below 0 or below
−1.5 kW per 1.6 t (an overrun cut-off), or both. Each is fitted on all model years but one
and scored on the held-out year (the newest and the oldest, as the study): mean |error| per
test and the mean signed and absolute error per schedule. Seconds.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=Path("../shared/data"))
    args = ap.parse_args(argv)
    import statsmodels.api as sm

    from sumo_drvpw.validation import epa_fleet as ef

    d, _ = ef.select(ef.read_lists(args.data / ef.DATASET), "gasoline")
    speeds = ef.schedules(args.data / ef.CYCLES)
    obs = ef.observations(d, speeds)
    obs = obs[obs["test"].isin(ef.TESTS)].reset_index(drop=True)
    cols = {k: [] for k in ("t_stand", "t_move", "t_over0", "t_over15")}
    for r in obs.itertuples(index=False):
        vm, p = ef.wheel_power(speeds[r.test], r.etw_kg, r.a_n / r.etw_kg, r.b_n_per_mps, r.c_n_per_mps2)
        mov = vm > 0.1
        cols["t_stand"].append(float((~mov).sum()))
        cols["t_move"].append(float(mov.sum()))
        cols["t_over0"].append(float((mov & (p < 0)).sum()))
        cols["t_over15"].append(float((mov & (p < -1500.0 * r.etw_kg / 1600.0)).sum()))
    for k, x in cols.items():
        obs[k] = x
    designs = {
        "one intercept (the fleet line)": lambda o: np.c_[o.displacement_l * o.t_s, o.traction_j],
        "standing and moving intercepts": lambda o: np.c_[o.displacement_l * o.t_stand, o.displacement_l * o.t_move,
                                                          o.traction_j],
        "overrun cut-off below 0 W": lambda o: np.c_[o.displacement_l * (o.t_s - o.t_over0), o.traction_j],
        "overrun cut-off below -1.5 kW": lambda o: np.c_[o.displacement_l * (o.t_s - o.t_over15), o.traction_j],
        "standing and moving, cut-off below 0 W": lambda o: np.c_[o.displacement_l * o.t_stand,
                                                                  o.displacement_l * (o.t_move - o.t_over0), o.traction_j],
    }
    years = sorted(obs["model_year"].unique())
    print(f"{len(obs)} tests of {obs['config'].nunique()} configurations, model years {[int(y) for y in years]}")
    for name, f in designs.items():
        print(name)
        for held in (years[-1], years[0]):
            tr, te = obs[obs["model_year"] != held], obs[obs["model_year"] == held]
            y = tr["fuel_j"].to_numpy()
            res = sm.WLS(y, f(tr), weights=1.0 / y ** 2).fit()
            e = f(te) @ res.params / te["fuel_j"].to_numpy() - 1.0
            per = ", ".join(f"{t} {np.mean(e[te['test'] == t]):+.1%}/{np.mean(np.abs(e[te['test'] == t])):.1%}"
                            for t in ("ftp_bag2", "ftp_bag3", "hwfet", "us06"))
            print(f"  {held} held out: mean |error| {np.mean(np.abs(e)):.2%}; intercepts "
                  f"{', '.join(f'{x:.0f}' for x in res.params[:-1])} W/L, η {1.0 / res.params[-1]:.3f}; {per}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
