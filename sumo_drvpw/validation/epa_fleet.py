"""Petrol and diesel cars' fuel from their road load: Willans chains calibrated on the US EPA Test Car List.

Run::

    .venv/bin/python -m sumo_drvpw.validation.epa_fleet [REPORT.md [DATA_FOLDER]]

writes the Markdown report (default ``docs/epa-fleet.md``), ``<out>.json`` beside it and the
built-in equations ``epa_<fuel>_car`` and ``epa_<fuel>_light_truck`` for petrol
(``gasoline``) and diesel (``sumo_drvpw/model/builtin/equations/``). Every number is
computed by the run.

**Data.** The Test Car List (``epa_test_car_list/*tstcar.csv``, one row per certification
test) gives, for every tested car configuration, the road load the chassis dynamometer
simulated — F = A + B·v + C·v² at the equivalent test weight (ETW) — and the fuel economy
it measured: per bag of the FTP-75, for the highway test (HWFET) and for US06. The speed
schedules are standard (``cycles/``). So every test is a known wheel-power trace with a
measured fuel energy: data for the tank end of the energy chain, from cars nobody here
tested, thousands of them.

**Model** (docs/energy-chain.md, ``predicts = "fuel"``), a conventional engine running for
the whole test (``engine_off_below_w = -inf``)::

    P_fuel = P_idle + max(P, 0)/η,     P_idle = p_L · D

η is the marginal efficiency fuel → wheels (the Willans slope, transmission included); the
fuel power with the engine running and no output scales with the displacement D [L]
(friction and pumping work per cycle scale with the swept volume). Per test
E_fuel = p_L·D·T + E⁺/η, with E⁺ = Σ max(P, 0)·Δt from the term basis (terms ``roll`` =
A/(m·g), ``v2`` = B, ``aero`` = C, ``acc``) and T the test's duration, fitted by weighted
least squares (statsmodels WLS, weight 1/E_fuel²: each test counts by its relative error).
The built-ins write the aerodynamic term as ``aero_rho`` = C_d·A = 2·C/ρ_ref
(:data:`COASTDOWN_RHO`), so that in a run it follows the run's air density.

**Selection** (fixed before any fit, from the file's own columns), per fuel: its
certification test fuel (:data:`TEST_FUELS`: ``Tier 2 Cert Gasoline``, ``Federal Cert
Diesel 7-15 PPM Sulfur``), measured (not analytically derived) tests, configurations with
a positive displacement, ETW, A and C and a road-load force > 0 up to 130 km/h; hybrids and
plug-ins left out (a configuration with a 4-bag FTP, a charge-depleting or electricity
test, or 'hybrid'/'plug-in' in its model name). Tests: FTP bag 2 (stabilised; UDDS
505–1369 s) and bag 3 (hot start; UDDS 0–505 s), HWFET, US06. Bag 1 (cold start) is not
on the Willans line; its excess over bag 3 — the same schedule, hot — is the fuel of a
cold start. The Cold CO test (the FTP at 20 °F, −6.7 °C; winter-grade test fuels) of the
same configurations gives the cold start in the cold: the chains' temperature slope is the
median over configurations tested both ways of (excess at −6.7 °C − excess on the FTP)
/ 30.6 K, written where at least :data:`MIN_COLD_PAIRS` configurations pair. A class with
fewer (the diesels: 3 cars, 6 light trucks) takes the relative slope — per kelvin, as a
share of the FTP cold start — pooled over every paired configuration of both fuels and
both bodies (the median), times its own FTP cold start (:func:`transfer_cold_slopes`; its
own few pairs are reported beside it as a check); with fewer than :data:`MIN_COLD_PAIRS`
pairs in all, its slope is 0.
Its bag 3 against the FTP's bag 3 (the same schedule, started hot after the same soak)
is a warm engine's extra fuel in the cold, the chains' ``running_fuel_per_k`` (per kelvin,
as a share; :mod:`sumo_drvpw.validation.epa_cold`, held out by model year); its bag 2
against the FTP's (still warming up) is reported. The winter-grade test fuels hold a little
less energy per litre than the certification fuel: part of these ratios (litres are
compared as measured), so the factor is an upper bound of the energy's. SC03 (A/C on) is
left out.

**Held out.** The newest model year is predicted by the fit on the older ones (other cars,
later technology), and the oldest by the fit on the newer ones. The built-ins are fitted
on every model year; their held-out quality is that of these splits. A class default
(medians of the class's road load per kg, ETW and displacement) is what a SUMO study
without the car's own data gets; its error on the held-out cars is reported beside the
error with each car's own road load.
"""

from __future__ import annotations

import re
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.constants import FUELS, G, LB, LBF, MILE, MPH

DATASET = "epa_test_car_list"
CYCLES = "cycles"
#: US gallon [L]
GALLON_L = 3.785411784
#: the fuels studied → the certification test fuel of their tests
TEST_FUELS = {"gasoline": "Tier 2 Cert Gasoline", "diesel": "Federal Cert Diesel 7-15 PPM Sulfur"}
#: words for the fuels in descriptions
FUEL_WORDS = {"gasoline": "petrol", "diesel": "diesel"}
#: FTP procedures (their FE Bag 1–3 are the FTP-75's bags)
FTP = ("Federal fuel 2-day exhaust (w/can load)", "Federal fuel 3-day exhaust",
       "CVS 75 and later (w/o can. load)")
HWFET = "HWFE"
US06 = "US06"
#: the tests on the Willans line: name → (schedule file, first s, last s)
TESTS = {"ftp_bag3": ("udds", 0, 505), "ftp_bag2": ("udds", 505, 1369),
         "hwfet": ("hwfet", 0, None), "us06": ("us06", 0, None)}
#: the cold start: FTP bag 1 on the schedule of bag 3
COLD = "ftp_bag1"
#: the FTP's nominal air temperature (75 °F; 68–86 °F allowed) and the Cold CO test's (20 °F) [°C]
FTP_AIR_C, COLD_CO_AIR_C = 23.9, -6.7
COLD_CO = "Cold CO"
#: configurations with both a Cold CO and an FTP test needed for a cold-start slope
MIN_COLD_PAIRS = 20
#: a Cold CO bag over the FTP's on the same schedule outside this range is a record error
RECORD_RATIO = (0.5, 2.0)
#: model-name words of hybrids and plug-ins
HYBRID_WORDS = re.compile(r"\b(?:hybrid|plug-in|phev|hev|e-hybrid|energi)\b", re.I)
#: road load must push back at every speed up to this [m/s]
MAX_CHECK_MPS = 130 / 3.6
#: EPA 'Vehicle Type' → built-in class
CLASSES = {"Car": "car", "Truck": "light_truck"}
#: built-in equations ``epa_<fuel>_<class>`` written by :func:`main`: class → (SUMO vClasses,
#: what it is); the SUMO run books each vehicle by the one of its emissionClass's fuel
BUILTINS = {
    "car": (("passenger", "private", "taxi", "hov", "vip", "authority"), "passenger car"),
    "light_truck": (("delivery", "emergency"), "light truck (pick-up, SUV, van: EPA 'Truck')"),
}
#: the air density the target coefficients are corrected to [kg/m³]: 40 CFR 1066.310's
#: reference (SAE J2263: 20 °C, 98.21 kPa, no wind); the built-ins' aerodynamic term is
#: C_d·A = 2·C/ρ_ref, so that a run's air (season, altitude) scales it
COASTDOWN_RHO = 1.17
#: plausible marginal efficiency fuel → wheels (petrol about 0.35, diesel about 0.4)
ETA_PLAUSIBLE = (0.25, 0.5)


# ---------------------------------------------------------------------- data
def read_lists(folder: Path) -> pd.DataFrame:
    """Every ``*tstcar.csv`` of ``folder``: one row per test, the columns used, in SI.

    Columns: ``model_year``, ``config`` (model year / test vehicle ID / configuration),
    ``make``, ``model``, ``vehicle_type``, ``displacement_l``, ``etw_kg``, ``a_n``,
    ``b_n_per_mps``, ``c_n_per_mps2``, ``procedure``, ``fuel``, ``derived``, ``fe_mpg``,
    ``fe_bag1..4`` [mpg]. UserError (naming the file and column) when one is missing.
    """
    files = sorted(Path(folder).glob("*tstcar.csv"))
    if not files:
        raise UserError(f"{folder}: no EPA Test Car List file (*tstcar.csv)")
    cols = {"Model Year": "model_year", "Test Vehicle ID": "vehicle_id",
            "Test Veh Configuration #": "config_no", "Represented Test Veh Make": "make",
            "Represented Test Veh Model": "model", "Vehicle Type": "vehicle_type",
            "Test Veh Displacement (L)": "displacement_l",
            "Equivalent Test Weight (lbs.)": "etw_lb", "Test Procedure Description": "procedure",
            "Test Fuel Type Description": "fuel", "Analytically Derived FE?": "derived",
            "RND_ADJ_FE": "fe_mpg", "FE Bag 1": "fe_bag1", "FE Bag 2": "fe_bag2",
            "FE Bag 3": "fe_bag3", "FE Bag 4": "fe_bag4", "Target Coef A (lbf)": "a_lbf",
            "Target Coef B (lbf/mph)": "b_lbf_per_mph", "Target Coef C (lbf/mph**2)": "c_lbf_per_mph2"}
    parts = []
    for f in files:
        try:  # MY2019's file ends lines in CR
            d = pd.read_csv(f, encoding="utf-8-sig", low_memory=False)
        except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError, OSError) as e:
            raise UserError(f"{f}: not a readable CSV file ({str(e).splitlines()[0] if str(e) else type(e).__name__})") from None
        d.columns = [str(c).strip() for c in d.columns]
        missing = [c for c in cols if c not in d.columns]
        if missing:
            raise UserError(f"{f}: column '{missing[0]}' not found (an EPA Test Car List has it)")
        d = d[list(cols)].rename(columns=cols)
        parts.append(d)
    d = pd.concat(parts, ignore_index=True)
    num = ["model_year", "displacement_l", "etw_lb", "fe_mpg", "fe_bag1", "fe_bag2", "fe_bag3",
           "fe_bag4", "a_lbf", "b_lbf_per_mph", "c_lbf_per_mph2"]
    for c in num:
        d[c] = pd.to_numeric(d[c], errors="coerce")
    for c in ("make", "model", "vehicle_type", "procedure", "fuel", "derived"):
        d[c] = d[c].astype(str).str.strip()
    d["config"] = (d["model_year"].astype("Int64").astype(str) + "/" + d["vehicle_id"].astype(str).str.strip()
                   + "/" + d["config_no"].astype(str).str.strip())
    d["etw_kg"] = d.pop("etw_lb") * LB
    d["a_n"] = d.pop("a_lbf") * LBF
    d["b_n_per_mps"] = d.pop("b_lbf_per_mph") * LBF / MPH
    d["c_n_per_mps2"] = d.pop("c_lbf_per_mph2") * LBF / MPH ** 2
    return d.drop(columns=["vehicle_id", "config_no"])


def select(d: pd.DataFrame, fuel: str = "gasoline") -> tuple[pd.DataFrame, dict]:
    """The conventional configurations' measured tests on ``fuel``'s certification test
    fuel, and the counts left out."""
    proc = d["procedure"]
    hybrid = (d["fe_bag4"].notna() & proc.isin(FTP)) | proc.str.startswith("Charge Depleting") \
        | d["fuel"].eq("Electricity") | d["model"].str.contains(HYBRID_WORDS)
    bad = set(d.loc[hybrid, "config"])
    physical = physical_road_load(d)
    keep = d["fuel"].eq(TEST_FUELS[fuel]) & d["derived"].eq("No")
    counts = {"tests": int(len(d)), "configurations": int(d["config"].nunique()),
              "hybrid, plug-in or electric configurations left out": len(bad),
              "tests of other fuels or analytically derived": int((~keep).sum()),
              "tests without a physical road load or displacement": int((keep & ~physical).sum())}
    out = d[keep & physical & ~d["config"].isin(bad)]
    return out, counts


def physical_road_load(d: pd.DataFrame) -> pd.Series:
    """Tests with a positive displacement, ETW, A and C and a road-load force > 0 at every
    speed up to :data:`MAX_CHECK_MPS`."""
    v = np.linspace(0.0, MAX_CHECK_MPS, 27)
    f = d["a_n"].to_numpy()[:, None] + d["b_n_per_mps"].to_numpy()[:, None] * v \
        + d["c_n_per_mps2"].to_numpy()[:, None] * v ** 2
    return ((d["displacement_l"] > 0) & (d["etw_kg"] > 0) & (d["a_n"] > 0) & (d["c_n_per_mps2"] > 0)
            & np.all(f > 0, axis=1))


def schedules(folder: Path) -> dict[str, np.ndarray]:
    """Speed [m/s] per second of each test of :data:`TESTS` (FASTSim cycle files)."""
    out = {}
    for name, (file, t0, t1) in TESTS.items():
        p = Path(folder) / f"{file}.csv"
        try:
            c = pd.read_csv(p)
            v = c["cycMps"].to_numpy(float)
        except (OSError, KeyError, ValueError) as e:
            raise UserError(f"{p}: cannot read the speed column 'cycMps' ({e})") from None
        out[name] = v[t0:None if t1 is None else t1 + 1]
    return out


def _distance_m(v: np.ndarray) -> float:
    """Distance [m] of a 1-s speed schedule (trapezoids)."""
    return float(0.5 * (v[1:] + v[:-1]).sum())


def _litres(dist_m: float, mpg):
    """Litres over ``dist_m`` at a fuel economy of ``mpg`` (US miles per gallon)."""
    return dist_m / MILE / mpg * GALLON_L


def observations(tests: pd.DataFrame, speeds: dict[str, np.ndarray], fuel: str = "gasoline") -> pd.DataFrame:
    """One row per (configuration, test on the Willans line): measured fuel energy
    ``fuel_j`` (FE → litres → J at the fuel's LHV and density), wheel traction energy
    ``traction_j`` (E⁺ from the term basis), duration ``t_s``, distance ``dist_m``; and the
    cold-start rows (``test`` = :data:`COLD`) for the excess of bag 1 over bag 3."""
    which = {"ftp_bag3": (tests["procedure"].isin(FTP), "fe_bag3"),
             "ftp_bag2": (tests["procedure"].isin(FTP), "fe_bag2"),
             COLD: (tests["procedure"].isin(FTP), "fe_bag1"),
             "hwfet": (tests["procedure"].eq(HWFET), "fe_mpg"),
             "us06": (tests["procedure"].eq(US06), "fe_mpg")}
    fp = FUELS[fuel]
    rows = []
    for test, (mask, col) in which.items():
        t = tests[mask & (tests[col] > 0)]
        if t.empty:
            continue
        v = speeds["ftp_bag3" if test == COLD else test]
        dist = _distance_m(v)
        e_pos = np.array([np.maximum(wheel_power(v, r.etw_kg, r.a_n / r.etw_kg, r.b_n_per_mps,
                                                 r.c_n_per_mps2)[1], 0.0).sum()
                          for r in t[["etw_kg", "a_n", "b_n_per_mps", "c_n_per_mps2"]].itertuples(index=False)])
        litres = _litres(dist, t[col].to_numpy(float))
        rows.append(pd.DataFrame({
            "config": t["config"].to_numpy(), "model_year": t["model_year"].to_numpy(int),
            "make": t["make"].to_numpy(), "model": t["model"].to_numpy(),
            "vehicle_type": t["vehicle_type"].to_numpy(), "displacement_l": t["displacement_l"].to_numpy(float),
            "etw_kg": t["etw_kg"].to_numpy(float), "a_n": t["a_n"].to_numpy(float),
            "b_n_per_mps": t["b_n_per_mps"].to_numpy(float), "c_n_per_mps2": t["c_n_per_mps2"].to_numpy(float),
            "test": test, "fuel_l": litres, "fuel_j": litres * fp["density_kg_per_l"] * fp["lhv_j_per_kg"],
            "traction_j": e_pos, "t_s": float(len(v) - 1), "dist_m": dist}))
    return pd.concat(rows, ignore_index=True)


def wheel_power(v: np.ndarray, mass_kg: float, a_n_per_kg: float, b_n_per_mps: float,
                c_n_per_mps2: float) -> tuple[np.ndarray, np.ndarray]:
    """Mean speed [m/s] and wheel power [W] of each 1-s step of schedule ``v`` for the road
    load F = A + B·v + C·v² (A = ``a_n_per_kg`` × mass) and inertia of ``mass_kg``, by the
    term basis (``roll`` = A/(m·g), ``v2`` = B, ``aero`` = C, ``acc``): the step's mean
    speed, and m·v̄·Δv, the step's exact kinetic-energy change."""
    from sumo_drvpw.model.equations import Equation
    from sumo_drvpw.model.terms import Inputs

    vm, dv = 0.5 * (v[1:] + v[:-1]), np.diff(v)
    z = np.zeros_like(vm)
    x = Inputs(v=vm, a=dv, theta=z, wind=z, mass=np.full_like(vm, float(mass_kg)), rho=np.ones_like(vm), v_acc=vm)
    eq = Equation(name="epa", terms={"roll": a_n_per_kg / G, "v2": b_n_per_mps, "aero": c_n_per_mps2, "acc": 1.0})
    return vm, eq.power(x)


# ---------------------------------------------------------------------- fit
def fit(obs: pd.DataFrame) -> dict:
    """Fleet Willans line on the observations' Willans tests: ``p_idle_w_per_l`` (p_L) and
    ``eta`` (η) with standard errors (statsmodels WLS, weights 1/E_fuel²)."""
    import statsmodels.api as sm

    o = obs[obs["test"].isin(TESTS)]
    if len(o) < 3:
        raise UserError("EPA fleet fit: fewer than 3 tests on the Willans line")
    x = np.column_stack([o["displacement_l"] * o["t_s"], o["traction_j"]])
    y = o["fuel_j"].to_numpy(float)
    res = sm.WLS(y, x, weights=1.0 / y ** 2).fit()
    p_l, inv_eta = (float(b) for b in res.params)
    se = np.asarray(res.bse, float)
    return {"p_idle_w_per_l": p_l, "p_idle_w_per_l_se": float(se[0]), "eta": 1.0 / inv_eta,
            "eta_se": float(se[1]) / inv_eta ** 2, "n_tests": int(len(o)),
            "n_configurations": int(o["config"].nunique())}


def chain_for(params: dict, displacement_l: float, fuel: str = "gasoline"):
    """The fuel chain of a car of displacement ``displacement_l`` [L] under fit ``params``."""
    from sumo_drvpw.model.chain import EnergyChain

    return EnergyChain(predicts="fuel", traction_efficiency=1.0, marginal_efficiency=params["eta"],
                       idle_fuel_power_w=params["p_idle_w_per_l"] * displacement_l,
                       engine_off_below_w=-np.inf, fuel=fuel)


def predict(obs: pd.DataFrame, params: dict, speeds: dict[str, np.ndarray], default: dict | None = None,
            mass_from_car: bool = True, fuel: str = "gasoline") -> np.ndarray:
    """Predicted fuel energy [J] of each observation through the evaluator
    (:meth:`EnergyChain.evaluate` on the term basis), with each car's own road load and
    displacement, or with the class ``default`` (per class: road load per kg, ETW,
    displacement; the car's ETW kept as the mass when ``mass_from_car``)."""
    out = np.empty(len(obs))
    for i, r in enumerate(obs.itertuples(index=False)):
        if default is None:
            m, a_per_kg, b, c, disp = r.etw_kg, r.a_n / r.etw_kg, r.b_n_per_mps, r.c_n_per_mps2, r.displacement_l
        else:
            dfl = default[CLASSES[r.vehicle_type]]
            m = r.etw_kg if mass_from_car else dfl["etw_kg"]
            a_per_kg, b, c, disp = dfl["a_n_per_kg"], dfl["b_n_per_mps"], dfl["c_n_per_mps2"], dfl["displacement_l"]
        vm, p = wheel_power(speeds["ftp_bag3" if r.test == COLD else r.test], m, a_per_kg, b, c)
        out[i] = chain_for(params, disp, fuel).evaluate(p, vm, dt_s=1.0)["power_j"].sum()
    return out


def class_defaults(obs: pd.DataFrame) -> dict:
    """Per class of :data:`CLASSES`: medians over its configurations of the road load per kg
    (A/m), B, C, ETW and displacement, and the number of configurations."""
    out = {}
    cars = obs.drop_duplicates("config")
    for vt, cls in CLASSES.items():
        c = cars[cars["vehicle_type"] == vt]
        if c.empty:
            continue
        out[cls] = {"a_n_per_kg": float((c["a_n"] / c["etw_kg"]).median()),
                    "b_n_per_mps": float(c["b_n_per_mps"].median()),
                    "c_n_per_mps2": float(c["c_n_per_mps2"].median()),
                    "etw_kg": float(c["etw_kg"].median()), "displacement_l": float(c["displacement_l"].median()),
                    "configurations": int(len(c))}
    return out


def _errors(obs: pd.DataFrame, pred: np.ndarray) -> dict:
    """Mean signed and mean absolute error (predicted/measured − 1) per test and per class."""
    e = pred / obs["fuel_j"].to_numpy(float) - 1.0
    out = {"all": _stat(e)}
    for t in TESTS:
        m = (obs["test"] == t).to_numpy()
        if m.any():
            out[t] = _stat(e[m])
    for vt, cls in CLASSES.items():
        m = (obs["vehicle_type"] == vt).to_numpy()
        if m.any():
            out[cls] = _stat(e[m])
    return out


def _stat(e: np.ndarray) -> dict:
    return {"n": int(e.size), "mean": float(e.mean()), "mean_abs": float(np.abs(e).mean()),
            "p90_abs": float(np.quantile(np.abs(e), 0.9))}


def split(obs: pd.DataFrame, test_years, speeds, fuel: str = "gasoline") -> dict:
    """Fit on the model years not in ``test_years``; errors on ``test_years`` with each
    car's own road load, and with the class defaults of the training cars."""
    test_years = tuple(int(y) for y in test_years)
    w = obs[obs["test"].isin(TESTS)]
    tr, te = w[~w["model_year"].isin(test_years)], w[w["model_year"].isin(test_years)]
    params = fit(tr)
    dfl = class_defaults(tr)
    own = _errors(te, predict(te, params, speeds, fuel=fuel))
    tec = te[te["vehicle_type"].isin(CLASSES)]
    return {"train_years": sorted(int(y) for y in tr["model_year"].unique()), "test_years": list(test_years),
            "fit": params, "own_road_load": own,
            "class_default_car_mass": _errors(tec, predict(tec, params, speeds, dfl, fuel=fuel)),
            "class_default": _errors(tec, predict(tec, params, speeds, dfl, mass_from_car=False, fuel=fuel)),
            "test_configurations": int(te["config"].nunique())}


def transfer_cold_slopes(results: dict) -> None:
    """For each fuel's class with fewer than :data:`MIN_COLD_PAIRS` paired configurations:
    the relative slope pooled over every paired configuration of ``results`` (fuel →
    :func:`study`; both fuels, both bodies), times the class's own FTP cold start, as
    ``cold_start_cold[cls]["transferred"]``; the built-in equations are rebuilt with it.

    The assumption: a cold start grows by the same share of itself per kelvin colder,
    whatever the engine (the warm-up's heat and friction scale with its own cold start).
    The class's own few pairs stay in the report beside it as a check.
    """
    pool = [x for r in results.values() for c in r.get("cold_start_cold", {}).values()
            for x in c.get("relative_per_k_pairs", [])]
    run = [x for r in results.values() for c in r.get("cold_start_cold", {}).values()
           for x in c.get("running_per_k_pairs", [])]
    if len(pool) < MIN_COLD_PAIRS:
        return
    rel = float(np.median(pool))
    for res in results.values():
        cc = res.setdefault("cold_start_cold", {})
        for cls in res["cold_start"]:
            if cc.get(cls, {}).get("configurations", 0) >= MIN_COLD_PAIRS:
                continue
            cc.setdefault(cls, {"configurations": 0})["transferred"] = {
                "from": "every paired configuration of both fuels", "pairs": len(pool),
                "relative_per_k": rel, "ml_per_k": rel * res["cold_start"][cls]["median_ml"],
                **({"running_per_k": float(np.median(run)), "running_pairs": len(run)}
                   if len(run) >= MIN_COLD_PAIRS else {})}
        res["equations"] = {c: builtin_equation(c, res) for c in res["equations"]}


def study(data: Path, fuel: str = "gasoline", lists: pd.DataFrame | None = None) -> dict:
    """The whole study of ``fuel`` on the shared data folder ``data`` (``lists``: the
    already read Test Car List, else read from the folder)."""
    from sumo_drvpw.validation.epa_cold import cold_start, cold_start_in_the_cold

    t0 = time.perf_counter()
    lists = read_lists(Path(data) / DATASET) if lists is None else lists
    d, counts = select(lists, fuel)
    speeds = schedules(Path(data) / CYCLES)
    if d.empty:
        raise UserError(f"{Path(data) / DATASET}: no conventional configuration tested on {TEST_FUELS[fuel]}")
    obs = observations(d, speeds, fuel)
    years = sorted(int(y) for y in obs["model_year"].unique())
    if len(years) < 2:
        raise UserError(f"{Path(data) / DATASET}: the held-out splits need two model years, found {years}")
    res = {"fuel": fuel, "counts": counts, "years": years,
           "tests_used": {t: int((obs["test"] == t).sum()) for t in list(TESTS) + [COLD]},
           "configurations_used": int(obs.loc[obs["test"].isin(TESTS), "config"].nunique()),
           "splits": {"newest held out": split(obs, [years[-1]], speeds, fuel),
                      "oldest held out": split(obs, [years[0]], speeds, fuel)},
           "fit_all": fit(obs), "defaults": class_defaults(obs[obs["test"].isin(TESTS)]),
           "cold_start": cold_start(obs),
           "cold_start_cold": cold_start_in_the_cold(lists, obs, speeds, fuel)}
    res["equations"] = {cls: builtin_equation(cls, res) for cls in res["defaults"] if cls in BUILTINS}
    res["seconds"] = time.perf_counter() - t0
    return res


# ---------------------------------------------------------------------- built-ins
def builtin_equation(cls: str, res: dict) -> dict:
    """The built-in equation document (TOML as a dict) of class ``cls`` from a study."""
    from sumo_drvpw.validation.epa_cold import cold_slope, running_slope

    vclasses, what = BUILTINS[cls]
    fuel = res["fuel"]
    name, what = f"epa_{fuel}_{cls}", f"{FUEL_WORDS[fuel]} {what}"
    p, dfl = res["fit_all"], res["defaults"][cls]
    hold = res["splits"]["newest held out"]
    own, dd = hold["own_road_load"], hold["class_default_car_mass"]
    years = f"{res['years'][0]}–{res['years'][-1]}"
    cold = res["cold_start"].get(cls, {})
    cc = res.get("cold_start_cold", {}).get(cls, {})
    slope_ml, slope_from = cold_slope(cc)
    slope = slope_ml / 1000.0
    run, run_from = running_slope(cc)
    return {
        "equation": {
            "name": name, "vclasses": list(vclasses),
            "description": (f"{what}: median road load of {dfl['configurations']} EPA-certified "
                            f"configurations (model years {years}) and a Willans fuel line fitted on their "
                            "certification tests; the mass comes from the vType"),
            "source": ("US EPA Test Car List (data.gov), model years " + ", ".join(map(str, res["years"]))
                       + "; fitted by python -m sumo_drvpw.validation.epa_fleet (docs/epa-fleet.md)"),
        },
        "terms": {"roll": round(dfl["a_n_per_kg"] / G, 6), "v2": round(dfl["b_n_per_mps"], 4),
                  "aero_rho": round(2.0 * dfl["c_n_per_mps2"] / COASTDOWN_RHO, 5), "acc": 1.0, "grade": 1.0},
        "provenance": {
            "aero_rho": (f"C_d·A = 2·C/ρ_ref [m²]: the class's median target coefficient C = "
                         f"{dfl['c_n_per_mps2']:.4f} N/(m/s)², corrected by the coastdown procedure to "
                         f"ρ_ref = {COASTDOWN_RHO} kg/m³ (40 CFR 1066.310; SAE J2263: 20 °C, 98.21 kPa); in a run "
                         "the aerodynamic force follows the run's air density (1.2041 kg/m³ by default: ×1.029)"),
            "roll": "A/(m·g): the target coefficient A per kg of test weight (tyres, driveline)",
            "v2": "B [N/(m/s)]: the target coefficient B (tyres, driveline; speed-proportional)",
        },
        "chain": {
            "predicts": "fuel", "traction_efficiency": 1.0,
            "marginal_efficiency": round(p["eta"], 4),
            "idle_fuel_power_w": round(p["p_idle_w_per_l"] * dfl["displacement_l"], 1),
            "engine_off_below_w": -np.inf, "aux_power_w": 0.0, "fuel": fuel,
            "cold_start_fuel_l": round(cold.get("median_ml", 0.0) / 1000.0, 4),
            "cold_start_fuel_l_per_k": round(max(slope, 0.0), 6), "cold_start_ref_c": FTP_AIR_C,
            "running_fuel_per_k": round(run, 6),
            "reading": {
                "marginal_efficiency": "fuel → wheels at the margin (Willans slope, transmission included)",
                "idle_fuel_power_w": (f"{p['p_idle_w_per_l']:.0f} W of fuel per litre of displacement × the "
                                      f"class median {dfl['displacement_l']:.1f} L: fuel with the engine running "
                                      "and no output (friction, pumping); for a known engine scale it by its "
                                      "displacement"),
                "engine_off_below_w": "-inf: a conventional engine runs the whole trip (idles at stops)",
                "aux_power_w": ("0: certification tests run without A/C; add the car's auxiliary draw "
                                "(W at the engine output) for real-world fuel"),
                "cold_start_fuel_l": (f"extra fuel of one cold start: FTP bag 1 − bag 3 of the same test, median "
                                      f"of {cold.get('configurations', 0)} configurations (IQR "
                                      f"{cold.get('q25_ml', float('nan')):.0f}–{cold.get('q75_ml', float('nan')):.0f} mL), "
                                      f"at the FTP's {FTP_AIR_C} °C; booked in SUMO only "
                                      "where the run says trips start cold ([vehicles] cold_start)"),
                "cold_start_fuel_l_per_k": (
                    f"more per kelvin colder than {FTP_AIR_C} °C: the Cold CO test (FTP at {COLD_CO_AIR_C} °C) of "
                    f"{cc.get('configurations', 0)} configurations also FTP-tested, median cold start "
                    f"{cc.get('cold_ml', float('nan')):.0f} mL against {cc.get('warm_ml', float('nan')):.0f} mL; "
                    "linear between the two temperatures, extrapolated below"
                    if slope_from == "own" else
                    (f"more per kelvin colder than {FTP_AIR_C} °C: {cc['transferred']['relative_per_k']:.2%} of the "
                     f"FTP cold start per kelvin, the median relative slope of {cc['transferred']['pairs']} "
                     "configurations of both fuels with a Cold CO test and an FTP; this class's "
                     f"own {cc.get('configurations', 0)} pairs are too few (fewer than {MIN_COLD_PAIRS})"
                     + (f" and give {cc['relative_per_k']:.2%}" if cc.get("configurations") else ""))
                    if slope_from == "transferred" else
                    f"0: {cc.get('configurations', 0)} configurations with a Cold CO test pair with an FTP "
                    f"(fewer than {MIN_COLD_PAIRS}); colder starts take more, not modelled"),
                "running_fuel_per_k": (
                    f"a warm engine's extra fuel per kelvin colder than {FTP_AIR_C} °C, as a share: the Cold CO "
                    f"test's bag 3 (hot start after a 10-min soak, at {COLD_CO_AIR_C} °C) over the FTP's bag 3, "
                    f"median ×{cc.get('bag3_ratio', float('nan')):.3f} over {cc.get('configurations', 0)} "
                    "configurations, linear between the two temperatures (driveline oil, tyres, engine "
                    "friction; the dynamometer's road load and so the air density are those of the FTP; "
                    "litres as measured, on the test's winter-grade fuel with a little less energy per litre: "
                    "an upper bound); "
                    "applied at a SUMO run's air temperature ([air] temperature_c; none given: 20 °C, and the run says so)"
                    if run_from == "own" else
                    (f"a warm engine's extra fuel per kelvin colder than {FTP_AIR_C} °C: the median over "
                     f"{cc['transferred'].get('running_pairs', 0)} configurations of both fuels with a Cold CO test "
                     f"and an FTP (bag 3 over bag 3); this class's own {cc.get('configurations', 0)} pairs are "
                     f"too few (fewer than {MIN_COLD_PAIRS})")
                    if run_from == "transferred" else
                    "0: too few configurations with a Cold CO test and an FTP; not modelled"),
            },
            "provenance": {
                "held_out": (f"model year {hold['test_years'][0]} predicted by the fit on "
                             f"{', '.join(map(str, hold['train_years']))}: fuel per test mean |error| "
                             f"{own['all']['mean_abs']:.1%} with each car's road load and displacement, "
                             f"{dd['all']['mean_abs']:.1%} with this class default (the car's ETW as mass)"),
                "etw_kg_median": round(dfl["etw_kg"], 1), "displacement_l_median": dfl["displacement_l"],
                "road_load_a_n_per_kg": dfl["a_n_per_kg"], "road_load_b_n_per_mps": dfl["b_n_per_mps"],
                "road_load_c_n_per_mps2": dfl["c_n_per_mps2"],
            },
        },
    }


def main(argv=None) -> int:
    """``python -m sumo_drvpw.validation.epa_fleet [REPORT.md [DATA_FOLDER]]`` (defaults
    docs/epa-fleet.md and $SUMO_DRVPW_DATA or ../shared/data): both fuels; also writes the
    built-in equations. Exit 2 with one line when the data are absent or unreadable."""
    from sumo_drvpw.fileio import plain, write_json, write_text
    from sumo_drvpw.model.equations import BUILTIN_DIR, equation_from_dict, save_equation
    from sumo_drvpw.validation.data import positional, resolve_data
    from sumo_drvpw.validation.epa_fleet_report import render

    t0 = time.perf_counter()
    try:
        args = positional(sys.argv[1:] if argv is None else argv, "REPORT.md [DATA_FOLDER]")
        out = Path(args[0] if args else "docs/epa-fleet.md")
        data = resolve_data(args[1] if len(args) > 1 else None, (DATASET, CYCLES))
        lists = read_lists(Path(data) / DATASET)
        results = {fuel: study(data, fuel, lists) for fuel in TEST_FUELS}
        transfer_cold_slopes(results)
    except UserError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    cmd = "python -m sumo_drvpw.validation.epa_fleet" + (f" {out}" if args else "")
    for res in results.values():
        for doc in res["equations"].values():
            save_equation(equation_from_dict(doc), BUILTIN_DIR / f"{doc['equation']['name']}.toml")
    write_json(out.with_suffix(".json"), plain(results))
    write_text(out, render(results, cmd, time.perf_counter() - t0))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
