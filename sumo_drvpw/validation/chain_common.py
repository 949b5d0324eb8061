"""Shared pieces of the energy-chain validation studies (:mod:`sumo_drvpw.validation.chain`,
:mod:`sumo_drvpw.validation.chain_i3`): reading a shared data set in place, net energy per
trip, the parameters of a chain fit."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

KWH = 3.6e6  # J per kWh


def read_shared(data: Path, folder: str, fmt: str, vehicle: str, add=None):
    """(log, vehicle) of a shared data set read in place through its adapter; ``add`` derives
    columns on the adapter's table before the log is built."""
    from sumo_drvpw.data import adapters
    from sumo_drvpw.data.log import from_frame
    from sumo_drvpw.model.vehicles import load_vehicle

    veh = load_vehicle(vehicle)
    df, _ = adapters.read(fmt, data / folder)
    if add is not None:
        df = add(df)
    return from_frame(df, veh, name=f"{folder}"), veh


def trip_rows(pred_w, meas_w, dt, trips, scale=KWH, unit="kwh") -> list[dict]:
    """Net energy per trip, predicted vs measured: Σ P·Δt over finite samples; with what
    each trip lost to the others (:func:`left_out`)."""
    ok = np.isfinite(pred_w) & np.isfinite(meas_w)
    lost = left_out(meas_w, ok, dt, trips)
    rows = []
    for t in dict.fromkeys(trips):
        s = ok & (trips == t)
        em = float(meas_w[s] @ dt[s]) / scale
        ep = float(pred_w[s] @ dt[s]) / scale
        rows.append({"trip": str(t), f"measured_{unit}": em, f"predicted_{unit}": ep,
                     "error": ep / em - 1.0 if em != 0 else math.nan, **lost[str(t)]})
    return rows


#: the left-out shares a per-trip row of the validation carries (fit/trip_energy.py)
LEFT_OUT_KEYS = ("left_out_time_share", "left_out_energy_share", "left_out_net_energy_share",
                 "left_out_power_unknown_time_share")


def left_out(meas_w, used, dt, trips) -> dict:
    """Per trip, the shares of its time and measured energy on the samples not ``used``
    (:func:`sumo_drvpw.fit.trip_energy.left_out_by_trip`) and ``partial``: True where they
    exceed :data:`~sumo_drvpw.fit.trip_energy.PARTIAL_TRIP_SHARE` (net energy: as compare
    flags a trip's net energy)."""
    from sumo_drvpw.fit.trip_energy import PARTIAL_TRIP_SHARE, left_out_by_trip, partial_share

    out = {}
    for t, d in left_out_by_trip(meas_w, used, dt, trips).items():
        out[t] = {k: d[k] for k in LEFT_OUT_KEYS}
        out[t]["partial"] = partial_share(d, net=True) > PARTIAL_TRIP_SHARE
    return out


def partial_lines(rows) -> list[str]:
    """The 'Partial trips' line of a per-trip table (as compare's report says it), from rows
    that carry :func:`left_out`'s keys; none when no trip is partial or the rows lack them."""
    from sumo_drvpw.fit.trip_energy import PARTIAL_TRIP_SHARE
    from sumo_drvpw.report.format import partial_trip_lines

    doc = {"trips": {r["trip"]: r for r in rows}, "partial_trip_share": PARTIAL_TRIP_SHARE,
           "partial_trips": [r["trip"] for r in rows if r.get("partial")]}
    lines = partial_trip_lines(doc, "energies in the table above (samples with a finite measured and "
                                    "predicted power)")
    return [""] + lines if lines else []


def mean_abs(rows, key="error", where=None) -> float:
    """Mean |row[key]| over rows with a finite value (and ``where(row)``); NaN when none."""
    e = [abs(r[key]) for r in rows if math.isfinite(r[key]) and (where is None or where(r))]
    return float(np.mean(e)) if e else math.nan


def params_of(fit) -> dict:
    """Value, standard error, bound flag and physical reading of each parameter of a chain fit."""
    return {k: {kk: p.get(kk) for kk in ("value", "std_err", "at_bound", "reading")}
            for k, p in fit.parameters.items()}

