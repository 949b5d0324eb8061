"""sumo_device.csv's row for an equation without an energy chain (an electric bus: no
battery chain applies to buses) says what it compares: the equation's net driving energy
at the wheels against SUMO's electricity, which adds SUMO's efficiencies and
constantPowerIntake. Real SUMO runs: the same buses with a vType exported from the
equation (efficiencies 1, no intake) and with SUMO's default efficiencies and an e-bus's
20-kW intake."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from sumo_drvpw.model.equations import load_equation
from sumo_drvpw.sim import run_scenario
from sumo_drvpw.sim.export import energy_vtype_xml

pytestmark = pytest.mark.sumo

REPO = Path(__file__).resolve().parent.parent
NET = REPO / "sumo_drvpw" / "sim" / "builtin" / "networks" / "city.net.xml"
EQ = "moves_transit_bus"  # a road-load equation: no chain applies to its buses
ROUTE = '<route edges="c00c10 c10c20 c20c30 c30c31 c31c32"/>'


def _run(d: Path, vtype: str | None, eq: str = EQ, routes: str | None = None):
    """A flow of four vehicles on the city net with equation ``eq`` and SUMO's device beside
    it: (its sumo_device.csv row, vehicles.parquet); ``vtype`` an additional file's vType of
    type ``ebus``, or ``routes`` a routes file of its own."""
    d.mkdir(exist_ok=True)
    if vtype is not None:
        (d / "bus.add.xml").write_text(vtype, encoding="utf-8")
    (d / "r.rou.xml").write_text(routes or (
        f'<routes><flow id="b" type="ebus" begin="0" end="60" period="15" departSpeed="0">{ROUTE}</flow></routes>\n'),
        encoding="utf-8")
    add = '\nadditional = ["bus.add.xml"]' if vtype is not None else ""
    (d / "s.toml").write_text(
        f'equations = ["{eq}"]\n[sumo]\nnet = "{NET}"\nroutes = ["r.rou.xml"]{add}\n'
        'begin = 0\nend = 400\nstep_length = 1.0\noptions = ["--no-warnings", "true"]\n'
        '[outputs]\nfigures = false\nsumo_device = true\n', encoding="utf-8")
    run_scenario(d / "s.toml", d / "o")
    row = pd.read_csv(d / "o" / "sumo_device.csv").set_index("equation").loc[eq]
    v = pd.read_parquet(d / "o" / "vehicles.parquet")
    return row, v


def test_a_row_without_chain_says_what_it_compares(tmp_path):
    """Exported vType: SUMO's electricity is the same road load without losses, the ratio
    near 1; SUMO's default efficiencies and a 20-kW intake: the same buses and the same
    ours, SUMO's total larger by its losses and intake (ratio 0.56, measured). Both rows say so in their
    note; before, the row had no note, and a ratio of 0.24 (H4's rehearsal, hilly network,
    11 e-buses) read as a model error."""
    xml, _ = energy_vtype_xml(load_equation(EQ), "ebus", mass_kg=13500, vclass="bus")
    exported, v1 = _run(tmp_path / "exported", xml)
    key = 'key="constantPowerIntake" value="'
    i = xml.index(key) + len(key)
    sumo_bus = xml[:i] + "20000" + xml[xml.index('"', i):]
    sumo_bus = "\n".join(line for line in sumo_bus.splitlines() if "Efficiency" not in line)  # SUMO's defaults
    own, v2 = _run(tmp_path / "own", sumo_bus)
    for row, v in ((exported, v1), (own, v2)):
        assert row["quantity"] == "net driving energy kWh (no chain)" and row["vehicles"] >= 3
        assert row["ours"] == pytest.approx(v[v.equation == EQ].net_total_j.sum() / 3.6e6, rel=1e-9)
        assert pd.isna(row["ratio_auxiliary"]) and pd.isna(row["ratio_rest"])
    # the exported vType's row says it is like for like (a rehearsal: "not like for like" at 0.9985)
    assert exported["note"].startswith("like for like") and "export-vtype" in exported["note"]
    note = own["note"]
    assert isinstance(note, str) and "not like for like" in note and "no energy chain" in note
    assert "constantPowerIntake" in note and "efficienc" in note and "export-vtype" in note
    assert exported["ours"] == pytest.approx(own["ours"], rel=1e-9)  # same buses, same driving
    assert exported["ratio"] == pytest.approx(1.0, abs=0.05)
    assert own["ratio"] < 0.7 * exported["ratio"]  # measured 0.564 vs 0.998


def test_a_full_hybrids_row_says_its_ratio_is_the_hybrids_saving(tmp_path):
    """The full-hybrid chain (engine off at light load, charge-sustaining) beside SUMO's
    emissions device, which books the vType's HBEFA class as a conventional engine (SUMO has
    no full-hybrid class): a rehearsal read its ratio 0.42 as an error. Its row now says
    what the ratio holds (a Hamburg run of hybrid cars, HBEFA4 PC_PHEV_petrol_(P)); a
    conventional petrol chain's row does not."""
    (tmp_path / "r.rou.xml").write_text(
        '<routes><vType id="hev" vClass="passenger" mass="1400" emissionClass="HBEFA4/PC_PHEV_petrol_Euro-6d_(P)"/>'
        '<vType id="car" vClass="passenger" mass="1400" emissionClass="HBEFA4/PC_petrol_Euro-6d"/>'
        '<flow id="h" type="hev" begin="0" end="60" period="15" departSpeed="0">'
        '<route edges="c00c10 c10c20 c20c30 c30c31 c31c32"/></flow>'
        '<flow id="p" type="car" begin="0" end="60" period="15" departSpeed="0">'
        '<route edges="c00c10 c10c20 c20c30 c30c31 c31c32"/></flow></routes>\n', encoding="utf-8")
    (tmp_path / "s.toml").write_text(
        f'equations = ["epa_gasoline_car", "epa_gasoline_hybrid_car"]\n[sumo]\nnet = "{NET}"\n'
        'routes = ["r.rou.xml"]\nbegin = 0\nend = 400\nstep_length = 1.0\noptions = ["--no-warnings", "true"]\n'
        '[outputs]\nfigures = false\nsumo_device = true\n', encoding="utf-8")
    run_scenario(tmp_path / "s.toml", tmp_path / "o")
    rows = pd.read_csv(tmp_path / "o" / "sumo_device.csv").set_index("equation")
    hev, car = rows.loc["epa_gasoline_hybrid_car"], rows.loc["epa_gasoline_car"]
    assert hev["vehicles"] == car["vehicles"] == 4
    assert "no full-hybrid car class" in hev["note"] and "saving" in hev["note"]
    assert not isinstance(car["note"], str) or "hybrid" not in car["note"]
    assert hev["ratio"] < car["ratio"]  # the same trips: the hybrid's engine-off and recovered braking


def test_a_plug_in_hybrids_row_says_its_litres_begin_after_its_battery(tmp_path):
    """The plug-in hybrid car's chain (epa_gasoline_phev_car: on its battery from departure) beside
    SUMO's emissions device on the same HBEFA 4 plug-in class: its short trips burn no fuel, and its
    row says why (the full hybrid's note did not: it named only the hybrid's saving)."""
    row, _ = _run(tmp_path, None, "epa_gasoline_phev_car", routes=(
        '<routes><vType id="phev" vClass="passenger" mass="1700" emissionClass="HBEFA4/PC_PHEV_petrol_Euro-6d_(P)"/>'
        f'<flow id="h" type="phev" begin="0" end="60" period="15" departSpeed="0">{ROUTE}</flow></routes>\n'))
    assert row["vehicles"] == 4 and row["ratio"] == 0.0   # every trip on its battery
    assert "on its charged battery" in row["note"] and "battery kWh are in chain_vehicles.csv" in row["note"]
