"""Can a state of charge stand in for the battery's V·I? A check on the shared BMW i3 trips,
which log both: the battery's voltage and current and the BMS's SOC (and the displayed SOC),
at 10 Hz.

    .venv/bin/python scripts/i3_soc_energy.py --data ../shared/data

Imports the trips twice, as a user would: with the i3 adapter (V·I), and through a
``columns`` mapping that maps the SOC and not V·I, with ``options.soc_capacity_kwh`` (the
battery energy the SOC's 0–100 % spans; :func:`sumo_drvpw.data.counters.soc_counters`).
Both are read as the battery target (:func:`sumo_drvpw.data.measured.load_measured`:
charging at standstill left out), and each trip's net battery energy is compared. The
capacity is not known from a datasheet for the BMS's SOC scale (60-Ah i3: 21.6 kWh gross,
18.8 kWh usable), so it is fitted — the ratio of the V·I energy to the SOC energy over one
season's trips — and each season is scored with the other season's capacity (held out);
in-sample, with the capacity of all trips, for reference. Prints per-trip errors (mean and
median |error|, worst) for the BMS SOC and the displayed SOC. About 1 min.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.data.measured import load_measured

#: the TUM CSVs' labels of what the SOC import reads (mapping TOML; V·I left out)
MAPPING = """[options]
sep = ";"
encoding = "latin-1"
keep_unmapped = false
soc_capacity_kwh = 10.0

[columns."Time [s]"]
name = "time_s"
[columns."Velocity [km/h]"]
name = "speed_mps"
unit = "km/h"
[columns."{soc}"]
name = "soc_pct"
"""


def trip_energy(path: Path):
    """Net battery energy per trip [kWh] of a canonical log, read as the battery target."""
    m = load_measured([path], "bmw_i3", target="battery")
    df = m.log.df
    e = np.nan_to_num(m.power_w) * df["dt_s"].to_numpy(float)
    return df.assign(e=e).groupby("trip_id")["e"].sum() / 3.6e6


def scores(err) -> str:
    i = int(np.argmax(err.abs().to_numpy()))
    return (f"mean |error| {100 * err.abs().mean():.1f} %, median {100 * err.abs().median():.1f} %, "
            f"worst {err.index[i]} {100 * err.iloc[i]:+.1f} %")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=Path("../shared/data"))
    args = ap.parse_args()
    trips = sorted((args.data / "bmw_i3_tum").glob("Trip*.csv"))
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        assert cli_main(["import", "bmw-i3-tum", *map(str, trips), "--out", str(d / "vi.parquet")]) == 0
        vi = trip_energy(d / "vi.parquet")
        for soc in ("SoC [%]", "displayed SoC [%]"):
            (d / "m.toml").write_text(MAPPING.format(soc=soc), encoding="utf-8")
            out = d / f"{len(soc)}.parquet"
            assert cli_main(["import", "columns", *map(str, trips), "--columns", str(d / "m.toml"),
                             "--out", str(out)]) == 0
            per = trip_energy(out) / 10.0  # kWh per kWh of capacity
            per = per[vi.index]
            print(f"\n{soc}: {len(vi)} trips, V·I {vi.sum():.2f} kWh net")
            cap = vi.sum() / per.sum()
            print(f"  in sample, capacity {cap:.2f} kWh (all trips): {scores(per * cap / vi - 1)}")
            names = vi.index.to_series()
            for fit, test in (("TripA", "TripB"), ("TripB", "TripA")):
                tr, te = names.str.startswith(fit), names.str.startswith(test)
                k = vi[tr].sum() / per[tr].sum()
                print(f"  capacity {k:.2f} kWh fitted on the {fit} trips, scored on the {int(te.sum())} "
                      f"{test} trips: {scores(per[te] * k / vi[te] - 1)}")


if __name__ == "__main__":
    main()
