"""The EPA Test Car List study's starts and warm running in the cold
(:mod:`sumo_drvpw.validation.epa_fleet` runs it): the cold start per class (FTP bag 1 −
bag 3 of the same test), the cold start at the Cold CO test's −6.7 °C and its slope per
kelvin, and a warm engine's extra fuel in the cold (the Cold CO test's bag 3 over the
FTP's: the same schedule, started hot after the same soak), held out by model year; and
which of them a built-in carries (its own, or pooled over both fuels' pairs).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from sumo_drvpw.validation.epa_fleet import (CLASSES, COLD, COLD_CO, COLD_CO_AIR_C, FTP_AIR_C, MIN_COLD_PAIRS,
                                             RECORD_RATIO, _distance_m, _litres)


def _cold_excess(obs: pd.DataFrame) -> tuple[pd.Series, pd.Series]:
    """Per configuration: the cold start (bag 1 − bag 3 of the same test, median over its
    tests) [mL], and its EPA vehicle type."""
    o = obs[obs["test"].isin((COLD, "ftp_bag3"))].copy()
    o["row"] = o.groupby(["config", "test"]).cumcount()
    wide = o.pivot_table(index=["config", "row", "vehicle_type"], columns="test", values="fuel_l").dropna()
    ex = (wide[COLD] - wide["ftp_bag3"]).groupby(level="config").median() * 1000.0
    vt = wide.reset_index().drop_duplicates("config").set_index("config")["vehicle_type"]
    return ex, vt


def cold_start_in_the_cold(lists: pd.DataFrame, obs: pd.DataFrame, speeds: dict, fuel: str = "gasoline") -> dict:
    """Per class: the cold start at −6.7 °C (Cold CO test, bag 1 − bag 3 [mL]) of the
    configurations that also have an FTP cold start in ``obs``, the median difference,
    its slope per kelvin between the two tests' temperatures; the Cold CO bag 3 over the
    FTP bag 3 — the same schedule, started hot after the same 10-min soak: a warm engine's
    fuel in the cold — as a share per kelvin (``running_per_k``, the built-ins'
    ``running_fuel_per_k``), held out by model year (:func:`_running_held_out`); and the
    Cold CO bag 2 over the FTP bag 2 (still warming up, reported); medians over paired
    configurations."""
    c = lists[lists["procedure"].eq(COLD_CO) & lists["derived"].eq("No")
              & (lists[["fe_bag1", "fe_bag2", "fe_bag3"]] > 0).all(axis=1)]
    diesel = c["fuel"].str.contains("diesel", case=False)
    c = c[diesel if fuel == "diesel" else ~diesel]
    dist = _distance_m(speeds["ftp_bag3"])  # bags 1 and 3
    cold = pd.DataFrame({"config": c["config"],
                         "cs_ml": 1000.0 * (_litres(dist, c["fe_bag1"]) - _litres(dist, c["fe_bag3"])),
                         "bag2_l": _litres(_distance_m(speeds["ftp_bag2"]), c["fe_bag2"]),
                         "bag3_l": _litres(dist, c["fe_bag3"])}
                        ).groupby("config").median()
    warm_cs, vt = _cold_excess(obs)
    warm = obs[obs["test"].isin(("ftp_bag2", "ftp_bag3"))].groupby(["config", "test"])["fuel_l"].median().unstack()
    year = obs.drop_duplicates("config").set_index("config")["model_year"]
    pair = cold.join(pd.DataFrame({"warm_ml": warm_cs, "warm_bag2_l": warm["ftp_bag2"], "warm_bag3_l": warm["ftp_bag3"],
                                   "vt": vt, "year": year}), how="inner").dropna()
    span = FTP_AIR_C - COLD_CO_AIR_C
    ratio = pair["bag3_l"] / pair["warm_bag3_l"]
    # a ratio beyond RECORD_RATIO (half or twice the fuel on the same schedule) is a record
    # error, not the cold: left out of the warm-running factor (counted)
    pair["running_per_k"] = ((ratio - 1.0) / span).where(ratio.between(*RECORD_RATIO))
    out = {}
    for t, cls in CLASSES.items():
        g = pair[pair["vt"] == t]
        if g.empty:
            continue
        diff = g["cs_ml"] - g["warm_ml"]
        out[cls] = {"configurations": int(len(g)), "cold_ml": float(g["cs_ml"].median()),
                    "warm_ml": float(g["warm_ml"].median()), "difference_ml": float(diff.median()),
                    "difference_q25_ml": float(diff.quantile(0.25)), "difference_q75_ml": float(diff.quantile(0.75)),
                    "ml_per_k": float(diff.median()) / (FTP_AIR_C - COLD_CO_AIR_C),
                    "relative_per_k": float((diff / g["warm_ml"]).median()) / (FTP_AIR_C - COLD_CO_AIR_C),
                    "relative_per_k_pairs": [round(float(x), 7) for x in
                                             diff / g["warm_ml"] / (FTP_AIR_C - COLD_CO_AIR_C)],
                    "bag2_ratio": float((g["bag2_l"] / g["warm_bag2_l"]).median()),
                    "bag3_ratio": float((g["bag3_l"] / g["warm_bag3_l"]).median()),
                    "bag3_ratio_q25": float((g["bag3_l"] / g["warm_bag3_l"]).quantile(0.25)),
                    "bag3_ratio_q75": float((g["bag3_l"] / g["warm_bag3_l"]).quantile(0.75)),
                    "running_per_k": float(g["running_per_k"].median()),
                    "running_per_k_pairs": [round(float(x), 7) for x in g["running_per_k"].dropna()],
                    "running_records_left_out": int(g["running_per_k"].isna().sum()),
                    "running_held_out": _running_held_out(g.dropna(subset=["running_per_k"]), span)}
    return out


def _running_held_out(g: pd.DataFrame, span: float) -> dict | None:
    """The warm-running factor held out by model year: the pairs of the newest model year
    predicted by the median factor of the older years' pairs — the Cold CO bag 3 from the
    FTP bag 3 as it is (no factor) and times (1 + r·ΔT); mean |error| of each. None with
    fewer than :data:`MIN_COLD_PAIRS` training pairs or no newer year."""
    years = sorted(g["year"].unique())
    tr, te = g[g["year"] < years[-1]], g[g["year"] == years[-1]]
    if len(years) < 2 or len(tr) < MIN_COLD_PAIRS:
        return None
    r = float(tr["running_per_k"].median())
    ratio = (te["bag3_l"] / te["warm_bag3_l"]).to_numpy(float)
    return {"train_years": [int(y) for y in years[:-1]], "test_year": int(years[-1]), "train_pairs": int(len(tr)),
            "test_pairs": int(len(te)), "running_per_k": r,
            "mean_abs_error_without": float(np.mean(np.abs(1.0 / ratio - 1.0))),
            "mean_abs_error_with": float(np.mean(np.abs((1.0 + r * span) / ratio - 1.0))),
            "mean_error_without": float(np.mean(1.0 / ratio - 1.0)),
            "mean_error_with": float(np.mean((1.0 + r * span) / ratio - 1.0))}


def running_slope(cc: dict) -> tuple[float, str]:
    """The warm-running fuel share per kelvin a built-in carries, and where it comes from
    ("own", "transferred" or "none"), as :func:`cold_slope`; never below 0."""
    if cc.get("configurations", 0) >= MIN_COLD_PAIRS:
        return max(cc["running_per_k"], 0.0), "own"
    if "running_per_k" in cc.get("transferred", {}):
        return max(cc["transferred"]["running_per_k"], 0.0), "transferred"
    return 0.0, "none"


def cold_slope(cc: dict) -> tuple[float, str]:
    """The slope [mL/K] a built-in carries, and where it comes from ("own", "transferred",
    or "none")."""
    if cc.get("configurations", 0) >= MIN_COLD_PAIRS:
        return cc["ml_per_k"], "own"
    if "transferred" in cc:
        return cc["transferred"]["ml_per_k"], "transferred"
    return 0.0, "none"


def cold_start(obs: pd.DataFrame) -> dict:
    """Fuel of a cold start per class: FTP bag 1 less bag 3 of the same test [mL]
    (medians and quartiles over configurations)."""
    ex, vt = _cold_excess(obs)
    out = {}
    for t, cls in CLASSES.items():
        x = ex[vt.reindex(ex.index) == t]
        if len(x):
            out[cls] = {"median_ml": float(x.median()), "q25_ml": float(x.quantile(0.25)),
                        "q75_ml": float(x.quantile(0.75)), "configurations": int(len(x))}
    return out
