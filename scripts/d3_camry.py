"""The petrol fuel chain on measured dynamometer tests nobody here wrote: Argonne's D3 tests
of a 2018 Toyota Camry XLE 2.5 L (8-speed automatic), as NREL's FASTSim ships them (1 Hz:
time, fuel flow, dynamometer speed), through the product's own commands.

    .venv/bin/python scripts/d3_camry.py --data DIR [--out docs/d3-camry.md]

DIR holds the four files ``618110NN Test Data.txt`` of FASTSim's
``python/fastsim/resources/calibration_demo_assets/dyno_data`` (github.com/NREL/fastsim,
commit bd9111bb; FASTSim's calibration demo names their source, anl.gov/taps/d3-2018-toyota-camry-xle).
Every number in the report is computed by the run (seconds).

What it does, as a user would: cuts each test's key-off periods (standing with no fuel for
5 s or more: the FTP's soak, the end of a test) and splits a test at such a soak into trips;
imports the files with the mapping of docs/adapters.md (`import columns`); takes the car's
EPA target road load and test weight (2019 Camry XLE/XSE 2.5 L, the same generation,
engine and transmission: ../shared/data/epa_test_car_list/19tstcar.csv) as the driving
power; then compares per trip, fuel energy predicted / measured − 1:

- ``epa_gasoline_car``: the built-in a SUMO study without logs uses (the class road load
  at the car's test weight);
- the EPA fleet's Willans line on the car's own road load and displacement (docs/epa-fleet.md);
- a fuel chain calibrated on the logs (`calibrate --target fuel`), each test held out in
  turn (trained on the other three).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import tempfile
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd

from sumo_drvpw.model.constants import LB, LBF, MPH  # noqa: F401  (LB, LBF: the planted test's too)

# 2019 CAMRY XLE/XSE, 2.487 L, 8 gears, ETW 3625 lb (19tstcar.csv, FTP and HWFE rows)
ETW_LB, A_LBF, B_LBF_MPH, C_LBF_MPH2, DISPLACEMENT_L = 3625.0, 26.509, 0.19851, 0.016476, 2.487
#: a flow below this [cc/s] is no fuel (the meter's zero)
NO_FUEL_CCPS = 0.02
FUEL_COLUMNS = ("Eng_FuelFlow_Direct_DI[ccps]", "Eng_FuelFlow_Direct[ccps]", "Eng_FuelFlow_Direct[cc/s]")
#: the overrun fuel cut-off declared in the variant [W]: where the table of zero-fuel share by
#: driving power on all four tests (exploratory, seen before this was fixed) crosses one half
FUEL_CUT_W = -1500.0
KEY_OFF_S = 5          # standing with no fuel this long: the key is off (soak), not a stop
SPLIT_GAP_S = 60.0     # a cut this long splits a test into trips


def _cli(*args) -> str:
    from sumo_drvpw.cli import main as cli_main

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(io.StringIO()):
        rc = cli_main([str(a) for a in args])
    if rc != 0:
        raise SystemExit(f"sumo-drvpw {' '.join(map(str, args[:2]))} failed (rc {rc})")
    return buf.getvalue()


def trim(src: Path, dst: Path) -> dict:
    """The test without its key-off periods, split at soaks into trips; what was measured."""
    d = pd.read_csv(src)
    fuel = next(c for c in FUEL_COLUMNS if c in d.columns)
    v, q, t = d["Dyno_Spd[mph]"].to_numpy() * MPH, d[fuel].to_numpy(), d["Time[s]"].to_numpy()
    from sumo_drvpw.data.dropouts import _runs

    keep = np.ones(len(d), bool)
    for a, b in zip(*_runs((v < 0.05) & (q < NO_FUEL_CCPS))):
        if b - a >= KEY_OFF_S:
            keep[a:b] = False
    k = np.flatnonzero(keep)
    part = np.concatenate([[0], np.cumsum(np.diff(t[k]) > SPLIT_GAP_S)])
    stem = src.stem.split()[0]
    e = d.iloc[k][["Time[s]", "Dyno_Spd[mph]", fuel]].rename(columns={fuel: "Eng_FuelFlow_Direct_DI[ccps]"})
    e["Trip"] = [stem + ("" if part.max() == 0 else "abcdefgh"[x]) for x in part]
    e.to_csv(dst, index=False)
    dt = np.gradient(t)
    moving = v > 1.0
    return {"test": stem, "seconds": float(t[-1] - t[0]), "key_off_s": float(dt[~keep].sum()),
            "km": float((v * dt).sum() / 1000), "litres": float((q * dt).sum() / 1000),
            "idle_lph": float(np.median(q[keep & (v < 0.05)]) * 3.6),
            "cut_share": float(dt[moving & (q < NO_FUEL_CCPS)].sum() / dt[moving].sum()), "trips": sorted(set(e["Trip"]))}


def trip_errors(report: Path) -> dict:
    r = json.loads((report / "report.json").read_text())
    return {name: {k: (t["measured_j"], t["predicted_j"], t["error"])
                   for k, t in e["trip_energy"]["trips"].items()} for name, e in r["equations"].items()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, required=True)
    ap.add_argument("--out", type=Path, default=Path("docs/d3-camry.md"))
    args = ap.parse_args(argv)
    files = sorted(args.data.glob("618110* Test Data.txt"))
    if len(files) != 4:
        print(f"{args.data}: expected FASTSim's four '618110NN Test Data.txt' files, found {len(files)}",
              file=sys.stderr)
        return 2
    from sumo_drvpw.model.equations import load_equation

    base = load_equation("epa_gasoline_car").chain
    p_l = base.idle_fuel_power_w / float(base.provenance["displacement_l_median"])
    rl = {"v1": A_LBF * LBF, "v2": B_LBF_MPH * LBF / MPH, "v3": C_LBF_MPH2 * LBF / MPH ** 2, "acc": 1.0,
          "grade": 1.0}
    etw = ETW_LB * LB
    with tempfile.TemporaryDirectory() as tmp:
        w = Path(tmp)
        (w / "map.toml").write_text('[columns."Time[s]"]\nname = "time_s"\n[columns."Dyno_Spd[mph]"]\n'
                                    'name = "speed_mps"\nunit = "mph"\n[columns."Eng_FuelFlow_Direct_DI[ccps]"]\n'
                                    'name = "fuel_rate_lph"\nunit = "cc/s"\n[columns."Trip"]\nname = "trip_id"\n')
        (w / "camry.toml").write_text(f'[vehicle]\nname = "camry2018"\nmass_kg = {etw:.2f}\n'
                                      f'[powertrain]\ndisplacement_l = {DISPLACEMENT_L}\n')
        terms = "".join(f"{k} = {x:.6g}\n" for k, x in rl.items())
        (w / "rl.toml").write_text(f'[equation]\nname = "camry_road_load"\nmass_kg = {etw:.2f}\n[terms]\n{terms}')
        (w / "fleet.toml").write_text(
            f'[equation]\nname = "fleet_line_own_road_load"\nmass_kg = {etw:.2f}\n[terms]\n{terms}'
            f'[chain]\npredicts = "fuel"\nidle_fuel_power_w = {p_l * DISPLACEMENT_L:.1f}\n'
            f'marginal_efficiency = {base.marginal_efficiency}\nengine_off_below_w = -inf\nfuel = "gasoline"\n')
        tests, logs = [], {}
        for f in files:
            info = trim(f, w / f"{f.stem.split()[0]}.csv")
            logs[info["test"]] = w / f"{info['test']}.parquet"
            _cli("import", "columns", w / f"{info['test']}.csv", "--columns", w / "map.toml", "--out", logs[info["test"]])
            tests.append(info)
        veh = ["--vehicle", w / "camry.toml"]
        prior = {}
        for t, log in logs.items():
            _cli("compare", log, *veh, "--equation", "epa_gasoline_car", "--equation", w / "fleet.toml",
                 "--target", "fuel", "--out", w / f"cmp{t}")
            for name, trips in trip_errors(w / f"cmp{t}").items():
                prior.setdefault(name, {}).update(trips)
        (w / "rlcut.toml").write_text((w / "rl.toml").read_text()
                                      + f'[chain]\npredicts = "fuel"\nfuel_cut_below_w = {FUEL_CUT_W}\n')
        held, fits = {"plain": {}, "cut": {}}, {"plain": {}, "cut": {}}
        for kind, eq in (("plain", "rl.toml"), ("cut", "rlcut.toml")):
            for t, log in logs.items():
                train = [x for k, x in logs.items() if k != t]
                out = w / f"cal{kind}{t}.toml"
                _cli("calibrate", *train, *veh, "--target", "fuel", "--equation", w / eq, "--out", out)
                fits[kind][t] = tomllib.loads(out.read_text())["chain"]
                _cli("compare", log, *veh, "--equation", out, "--target", "fuel", "--out", w / f"held{kind}{t}")
                held[kind].update(next(iter(trip_errors(w / f"held{kind}{t}").values())))
        zero = cut_table(w, logs)
    args.out.write_text(report(tests, prior, held, fits, etw, rl, base, zero), encoding="utf-8")
    print(f"wrote {args.out}")
    return 0


def cut_table(w: Path, logs: dict) -> list[tuple[str, int, float]]:
    """Share of the moving samples with no fuel, by driving power band (all tests; the
    driving power of the road-load equation ``w/rl.toml`` as the commands take it)."""
    from sumo_drvpw.data.measured import load_measured
    from sumo_drvpw.model.equations import load_equation

    eq = load_equation(w / "rl.toml")
    m = load_measured(list(logs.values()), w / "camry.toml", target="fuel")
    p, v = eq.power(m.inputs.with_mass(eq.mass_kg)), np.asarray(m.inputs.v)
    q = m.log.df["fuel_rate_lph"].to_numpy(float) / 3.6  # cc/s
    moving = m.usable & (v > 1.0)
    edges = [-np.inf, -10e3, -5e3, -2e3, -1e3, 0.0, 1e3, 2e3, np.inf]
    out = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        b = moving & (p >= lo) & (p < hi)
        if b.any():
            out.append((f"{lo / 1e3:g} … {hi / 1e3:g}", int(b.sum()), float((q[b] < NO_FUEL_CCPS).mean())))
    return out


def _mean_abs(d: dict, keys) -> float:
    return float(np.mean([abs(d[k][2]) for k in keys]))


def report(tests, prior, held, fits, etw, rl, base, zero) -> str:
    from sumo_drvpw.model.constants import FUELS

    fp = FUELS["gasoline"]
    j_per_l = fp["lhv_j_per_kg"] * fp["density_kg_per_l"]
    hp, hc = held["plain"], held["cut"]
    trips = sorted(hp)
    cold = [k for k in trips if k.endswith("a") and k[:-1] + "b" in hp]  # the FTP's cold UDDS
    hot = [k for k in trips if k not in cold]
    a, b = prior["epa_gasoline_car"], prior["fleet_line_own_road_load"]
    L = ["# The petrol fuel chain on Argonne's D3 tests of a 2018 Toyota Camry", "",
         "Generated by `.venv/bin/python scripts/d3_camry.py --data DIR` (DIR: FASTSim's "
         "`python/fastsim/resources/calibration_demo_assets/dyno_data`, github.com/NREL/fastsim "
         "commit bd9111bb); every number below is computed by that run. Method: the script's docstring. "
         "One car on a dynamometer (no wind, no grade; the test cell's temperature is not in these files): "
         "a hint for the fuel chains, not a validation of them.", "",
         "## The tests", "",
         "| test | s | key-off cut [s] | km | L | L/100 km | standing fuel [L/h] | moving time without fuel | trips |",
         "|---|---|---|---|---|---|---|---|---|"]
    for t in tests:
        L.append(f"| {t['test']} | {t['seconds']:.0f} | {t['key_off_s']:.0f} | {t['km']:.2f} | {t['litres']:.3f} | "
                 f"{100 * t['litres'] / t['km']:.2f} | {t['idle_lph']:.2f} | {t['cut_share']:.0%} | "
                 f"{', '.join(t['trips'])} |")
    L += ["", "Read from the schedules: 61811011 is an FTP with both UDDS runs (cold, a ten-minute soak, "
          "hot: trips a and b), 61811012 a hot UDDS, 61811013 two HWFETs, 61811014 two US06s. "
          "The EPA's 2019 Camry XLE/XSE (same engine and transmission) reads 37.0 mpg on the FTP and "
          "58.2 on the HWFET (19tstcar.csv); these tests, fuel over distance of the whole test (not the FTP's "
          "weighting of its bags): "
          f"{235.215 / (100 * tests[0]['litres'] / tests[0]['km']):.1f} and "
          f"{235.215 / (100 * tests[2]['litres'] / tests[2]['km']):.1f} mpg.", "",
          f"Driving power: the EPA target road load A {rl['v1']:.1f} N, B {rl['v2']:.3f} N/(m/s), "
          f"C {rl['v3']:.4f} N/(m/s)², the test weight {etw:.0f} kg as the inertia the dynamometer "
          "simulates, the acceleration from the 1-Hz speed.", "",
          "## Fuel per trip, predicted / measured − 1", "",
          "| trip | measured [kWh of fuel] | `epa_gasoline_car` (class road load, test weight) | "
          "fleet line, the car's road load and 2.487 L | calibrated on the other tests | "
          f"the same, overrun cut-off declared below {FUEL_CUT_W / 1e3:g} kW |", "|---|---|---|---|---|---|"]
    for k in trips:
        L.append(f"| {k}{' (cold start)' if k in cold else ''} | {hp[k][0] / 3.6e6:.3f} | {a[k][2]:+.1%} | "
                 f"{b[k][2]:+.1%} | {hp[k][2]:+.1%} | {hc[k][2]:+.1%} |")
    L.append(f"| mean abs., warm trips ({len(hot)}) | | {_mean_abs(a, hot):.1%} | {_mean_abs(b, hot):.1%} | "
             f"{_mean_abs(hp, hot):.1%} | {_mean_abs(hc, hot):.1%} |")
    L += ["", "## The calibrated chains (each trained without one test)", "",
          "| held out | variant | idle fuel [W] (L/h) | η_m | engine off below | flagged IMPLAUSIBLE |",
          "|---|---|---|---|---|---|"]
    for kind in ("plain", "cut"):
        for t, c in fits[kind].items():
            flags = [k for k, r in c.get("reading", {}).items() if "IMPLAUSIBLE" in r]
            L.append(f"| {t} | {'cut-off declared' if kind == 'cut' else 'as calibrated'} | "
                     f"{c['idle_fuel_power_w']:.0f} ({c['idle_fuel_power_w'] * 3600 / j_per_l:.2f}) | "
                     f"{c['marginal_efficiency']:.3f} | {c['engine_off_below_w']} | {', '.join(flags) or '–'} |")
    L += ["", "Moving samples (above 1 m/s) without fuel (below 0.02 cc/s), by driving power [kW]: "
          + "; ".join(f"{band}: {share:.0%} of {n}" for band, n, share in zero) + "."]
    if cold:
        k = cold[0]
        extra = (hp[k][0] - hp[k[:-1] + "b"][0])
        L += ["", f"Cold start: the cold UDDS ({k}) burnt {extra / 3.6e6:.3f} kWh of fuel more than the hot one "
              f"after the soak ({k[:-1]}b), {extra / j_per_l * 1000:.0f} mL of petrol; the built-in's "
              f"`cold_start_fuel_l` (the fleet's median FTP bag 1 − bag 3) is {base.cold_start_fuel_l * 1000:.0f} mL."]
    worst = max(hot, key=lambda k: abs(hp[k][2]))
    L += ["", "## Reading", "",
          f"- The class default books this car {_mean_abs(a, hot):.0%} high on its warm trips, and the fleet's "
          f"line with the car's own road load {_mean_abs(b, hot):.0%}: this 2.5-litre engine and eight-speed "
          "gearbox burn less than the EPA fleet's line (docs/epa-fleet.md: with their own road load, 90 % of "
          "model year 2022's configurations, held out, within 17.6 %). For one car without logs, that is the "
          "uncertainty a SUMO study carries.",
          f"- Calibrated on three tests, the chain misses the fourth by {_mean_abs(hp, hot):.1%} on average; the "
          f"worst is {worst} ({hp[worst][2]:+.1%}). A line with one intercept cannot follow an engine whose "
          "friction fuel depends on its speed: trained without the highway test, it books the highway's low "
          "engine speed in top gear too high, as the fleet study found.",
          "- The calibration flags the idle fuel of the folds where it falls below the idle of a "
          "2.5-litre engine; the tests' standing fuel is the table's. The overrun cut-offs (moving without "
          "fuel) pull the line's intercept down. Declared (the last column), the intercept rises toward "
          f"the measured idle, but the held-out error is {_mean_abs(hc, hot):.1%} against "
          f"{_mean_abs(hp, hot):.1%}: the intercept in gear is not the standing idle's either.",
          "- Before fit/chain_fuel.py's idling rule, the fold without the US06 read this car as an engine "
          "that stops at P ≤ 0 with an auxiliary draw of 1.8 kW; the car idles at every stop (the standing "
          "fuel above), and the calibration now fits it as an engine that runs at standstill."]
    return "\n".join(L) + "\n"


if __name__ == "__main__":
    sys.exit(main())
