"""chain_vehicles.csv of a run whose vehicles are written out in parts (bounded memory):
every part carries the columns of every chain of the run, whatever chains its first part's
vehicles had. Real SUMO run on the bundled city net."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("libsumo")

REPO = Path(__file__).resolve().parent.parent
NET = REPO / "sumo_drvpw" / "sim" / "builtin" / "networks" / "city.net.xml"


def test_battery_rows_keep_their_values_when_the_first_vehicles_written_out_burn_fuel(tmp_path):
    """Petrol cars leave first (written out two at a time), electric cars later: before
    (2026-11-27 rehearsal), the parts' columns were those of the first part's rows, so the
    electric cars' kWh were dropped from chain_vehicles.csv (their net_kwh empty) and, on
    the Dask FCD engine, buckets whose first rows differed wrote columns in another order
    (a hilly Bologna run: net_kwh summed 4,780.65 against 62.06 kWh). Now the per-vehicle
    rows add up to the class totals for every quantity."""
    import pandas as pd

    from sumo_drvpw.sim import run_scenario

    (tmp_path / "r.rou.xml").write_text("""<routes>
    <vType id="ev" vClass="passenger" emissionClass="Energy/unknown" mass="1600"/>
    <vType id="petrol" vClass="passenger" emissionClass="HBEFA4/PC_petrol_Euro-4" mass="1400"/>
    <flow id="p" type="petrol" begin="0" end="30" period="5" departSpeed="0"><route edges="c00c10 c10c20"/></flow>
    <flow id="e" type="ev" begin="150" end="180" period="5" departSpeed="0"><route edges="c00c10 c10c20"/></flow>
</routes>
""", encoding="utf-8")
    (tmp_path / "c.sumocfg").write_text(f"""<configuration>
    <input><net-file value="{NET}"/><route-files value="r.rou.xml"/></input>
    <time><begin value="0"/><end value="400"/></time>
    <report><no-warnings value="true"/></report>
</configuration>
""", encoding="utf-8")
    (tmp_path / "s.toml").write_text('equations = ["epa_gasoline_car", "bmw_i3_battery"]\n[sumo]\n'
                                     'config = "c.sumocfg"\n[vehicles]\ncold_start = 0.5\n'
                                     '[outputs]\nfigures = false\n', encoding="utf-8")
    out = tmp_path / "o"
    run_scenario(tmp_path / "s.toml", out, flush_vehicles=2)
    veh = pd.read_csv(out / "chain_vehicles.csv", dtype={"key": str})
    cls = pd.read_csv(out / "chain_classes.csv")
    assert set(veh.equation) == {"epa_gasoline_car", "bmw_i3_battery"}
    ev = veh[veh.equation == "bmw_i3_battery"]
    assert len(ev) >= 5 and ev.key.str.startswith("e").all() and ev.net_kwh.notna().all()
    for eq, q in [("bmw_i3_battery", "net_kwh"), ("bmw_i3_battery", "auxiliary_kwh"),
                  ("epa_gasoline_car", "fuel_l"), ("epa_gasoline_car", "cold_start_l"),
                  ("bmw_i3_battery", "distance_km"), ("epa_gasoline_car", "distance_km")]:
        total = cls[cls.equation == eq][q].sum()
        assert total > 0
        assert veh[veh.equation == eq][q].sum() == pytest.approx(total, rel=1e-9), (eq, q)
