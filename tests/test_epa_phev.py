"""The built-in plug-in hybrid car ``epa_gasoline_phev_car`` (validation/epa_phev.py): its
derivation, and a bare SUMO config booking HBEFA 4's plug-in hybrids with it — on its battery
from departure until the usable energy is spent, then on fuel — live and replayed from its FCD."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from sumo_drvpw.model.equations import load_equation
from sumo_drvpw.validation import epa_phev as ep


def test_its_battery_is_fastsims_plug_in_hybrids_median_and_its_fuel_the_full_hybrids():
    """Usable energy by hand: 8.8 × 0.65, 18.4 × 0.75, 7.6 × 0.75, 9.8 × 0.75 kWh = 5.72, 13.8,
    5.7, 7.35: median 6.535 kWh; η_t = 0.98 × 0.92 × √0.97; the limit the median of 53, 111, 65,
    50 kW. Once spent, the full hybrid's chain to the key."""
    dep = ep.depleting()
    assert dep["usable_j"] == pytest.approx((5.72 + 7.35) / 2 * 3.6e6, abs=500.0)
    assert dep["traction_efficiency"] == pytest.approx(0.98 * 0.92 * 0.97 ** 0.5, abs=1e-4)
    assert dep["recuperation_efficiency"] == pytest.approx(0.98 * dep["traction_efficiency"], abs=1e-4)
    assert dep["recuperation_limit_w"] == 59000.0
    eq, full = load_equation(ep.NAME), load_equation(ep.FULL_HYBRID)
    assert eq.chain.depleting.usable_j == dep["usable_j"]
    assert eq.chain.depleting.chain.traction_efficiency == dep["traction_efficiency"]
    sustaining = {k: x for k, x in eq.chain.to_dict().items() if k not in ("depleting", "reading", "provenance")}
    assert sustaining == {k: x for k, x in full.chain.to_dict().items() if k not in ("reading", "provenance")}


def test_the_built_in_is_what_the_derivation_writes(shared_data):
    doc, took = ep.builtin_equation(shared_data)
    eq = load_equation(ep.NAME)
    assert took["configurations"] >= 10 and len(took["years"]) >= 2
    assert dict(eq.terms) == pytest.approx(doc["terms"])
    dep = eq.chain.to_dict()["depleting"]
    assert {k: dep[k] for k in doc["chain"]["depleting"]} == pytest.approx(doc["chain"]["depleting"])


ROUTES = """<routes>
  <vType id="phev" emissionClass="HBEFA4/PC_PHEV_petrol_Euro-6d_(P)" mass="1900" maxSpeed="30"/>
  <vType id="petrol" emissionClass="HBEFA4/PC_petrol_Euro-6d" mass="1400" maxSpeed="30"/>
  <vehicle id="h" type="phev" depart="0"><route edges="e0 e1 e2 e3 e4 e5"/></vehicle>
  <vehicle id="p" type="petrol" depart="1"><route edges="e0 e1 e2 e3 e4 e5"/></vehicle>
</routes>"""


@pytest.mark.sumo
def test_a_bare_config_runs_a_plug_in_hybrid_on_its_battery_then_on_fuel_live_and_replayed(tmp_path, capsys):
    """60 km at up to 30 m/s, six 10-km edges: the plug-in hybrid's vType is booked by
    ``epa_gasoline_phev_car`` alone (summary.json says so: its powertrain, not booked by the
    petrol or the full hybrid's chain, charged at departure); it spends exactly its usable
    battery energy — the first edges on battery and no fuel, the last on fuel and no battery —;
    vehicle, edge and class totals agree; the FCD replay books the same; the console gives its
    class's battery beside its litres."""
    pytest.importorskip("libsumo")
    from sumo_drvpw.cli import main as cli_main
    from sumo_probe import build_net

    nodes = "".join(f'<node id="n{i}" x="{10000 * i}" y="0"/>' for i in range(7))
    edges = "".join(f'<edge id="e{i}" from="n{i}" to="n{i + 1}" numLanes="1" speed="30"/>' for i in range(6))
    build_net(tmp_path, f"<nodes>{nodes}</nodes>", f"<edges>{edges}</edges>")
    (tmp_path / "r.rou.xml").write_text(ROUTES, encoding="utf-8")
    (tmp_path / "c.sumocfg").write_text(
        '<configuration><input><net-file value="n.net.xml"/><route-files value="r.rou.xml"/></input>'
        '<output><fcd-output value="fcd.xml"/><precision value="6"/></output>'
        '<time><end value="2600"/></time></configuration>', encoding="utf-8")
    assert cli_main(["run", str(tmp_path / "c.sumocfg"), "--no-figures", "--out", str(tmp_path / "live")]) == 0
    said = [ln for ln in capsys.readouterr().out.splitlines() if ln.strip().startswith(f"{ep.NAME} fuel, passenger")]
    assert cli_main(["fcd", str(tmp_path / "live" / "sumo" / "fcd.xml"), "--scenario", str(tmp_path / "c.sumocfg"),
                     "--no-figures", "--out", str(tmp_path / "replay")]) == 0
    usable_kwh = load_equation(ep.NAME).chain.depleting.usable_j / 3.6e6
    assert len(said) == 1 and f"battery net {usable_kwh:.2f} kWh" in said[0]
    books = {}
    for run in ("live", "replay"):
        out = tmp_path / run
        summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
        pt = summary["assumptions"]["powertrain"]["phev"]
        assert pt["powertrain"] == "plug-in hybrid" and pt["battery"].startswith("charged at each departure")
        assert set(pt["not_booked_by"]) == {"epa_gasoline_car", "epa_gasoline_hybrid_car"}
        veh = pd.read_csv(out / "chain_vehicles.csv", dtype={"key": str})
        mine = veh[veh["equation"] == ep.NAME]
        assert list(mine["key"]) == ["h"]   # the petrol car is not its
        h = mine.iloc[0]
        assert h["net_kwh"] == pytest.approx(usable_kwh, rel=1e-6)   # all of its usable energy, no more
        assert h["fuel_l"] > 0.5
        edges = pd.read_csv(out / "chain_edges.csv", dtype={"key": str})
        e = edges[edges["equation"] == ep.NAME].set_index("key")
        assert e.loc["e0", "fuel_l"] == 0.0 and e.loc["e0", "net_kwh"] > 0.0       # departs on its battery
        assert e.loc["e5", "net_kwh"] == 0.0 and e.loc["e5", "fuel_l"] > 0.0       # arrives on fuel
        cls = pd.read_csv(out / "chain_classes.csv", dtype={"key": str})
        c = cls[cls["equation"] == ep.NAME]
        for col in ("fuel_l", "net_kwh", "traction_kwh"):
            assert e[col].sum() == pytest.approx(h[col], rel=1e-9, abs=1e-12)
            assert c[col].sum() == pytest.approx(h[col], rel=1e-9, abs=1e-12)
        books[run] = h
    for col in ("fuel_l", "net_kwh", "traction_kwh", "recuperated_kwh"):
        assert books["replay"][col] == pytest.approx(books["live"][col], rel=1e-6, abs=1e-9)


def test_powertrain_of_a_class_and_a_resolver_with_a_plain_name_beside_the_plug_in():
    """HBEFA 4's PHEV classes are plug-in hybrids, HEV/hybrid names full hybrids, the rest
    conventional; an equation given by its plain name (booking any vType) beside the plug-in
    built-in does not stop the resolver."""
    from types import SimpleNamespace

    from sumo_drvpw.sim.powertrain import powertrain_of_class
    from sumo_drvpw.sim.resolver import VTypeResolver

    assert [powertrain_of_class(c) for c in ("HBEFA4/PC_PHEV_petrol_Euro-6d_(P)", "HBEFA4/UBus_Std_gt15-18t_HEV_Euro-VI_D-E",
                                             "HBEFA4/PC_petrol_Euro-6d", None)] == [
        "plug-in hybrid", "hybrid", "conventional", "conventional"]
    r = VTypeResolver(SimpleNamespace(), {}, ["road", load_equation(ep.NAME), load_equation(ep.FULL_HYBRID)])
    assert r.plug_in == {ep.NAME}
