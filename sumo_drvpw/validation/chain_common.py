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
    """Net energy per trip, predicted vs measured: Σ P·Δt over finite samples."""
    ok = np.isfinite(pred_w) & np.isfinite(meas_w)
    rows = []
    for t in dict.fromkeys(trips):
        s = ok & (trips == t)
        em = float(meas_w[s] @ dt[s]) / scale
        ep = float(pred_w[s] @ dt[s]) / scale
        rows.append({"trip": str(t), f"measured_{unit}": em, f"predicted_{unit}": ep,
                     "error": ep / em - 1.0 if em != 0 else math.nan})
    return rows


def mean_abs(rows, key="error", where=None) -> float:
    """Mean |row[key]| over rows with a finite value (and ``where(row)``); NaN when none."""
    e = [abs(r[key]) for r in rows if math.isfinite(r[key]) and (where is None or where(r))]
    return float(np.mean(e)) if e else math.nan


def params_of(fit) -> dict:
    """Value, standard error, bound flag and physical reading of each parameter of a chain fit."""
    return {k: {kk: p.get(kk) for kk in ("value", "std_err", "at_bound", "reading")}
            for k, p in fit.parameters.items()}

