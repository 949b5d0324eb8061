"""Energy per trip (issue #11 §5): traction and net energy, predicted against measured."""

import json

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from sumo_drvpw.fit.compare import compare, trip_energy, trip_net_energy
from sumo_drvpw.model.equations import Equation
from sumo_drvpw.model.terms import Inputs


def test_hand_computed_two_trips():
    # trip a: meas 10,-5,20 W over 0.5 s -> traction 15 J; pred 12,-1,18 -> 15 J
    # trip b: meas 4,4 W over 1 s -> 8 J; pred 6,2 -> 8 J traction, error 0; net same
    meas = np.array([10.0, -5.0, 20.0, 4.0, 4.0])
    pred = np.array([12.0, -1.0, 18.0, 6.0, 2.0])
    dt = np.array([0.5, 0.5, 0.5, 1.0, 1.0])
    trip = np.array(["a", "a", "a", "b", "b"])
    out = trip_energy(pred, meas, dt, trip)
    assert list(out["trips"]) == ["a", "b"]
    assert out["trips"]["a"]["measured_j"] == pytest.approx(15.0)
    assert out["trips"]["a"]["predicted_j"] == pytest.approx(15.0)
    assert out["trips"]["b"]["error"] == pytest.approx(0.0)
    net = trip_net_energy(pred, meas, dt, trip)
    assert net["trips"]["a"]["measured_j"] == pytest.approx(12.5)   # (10-5+20)*0.5
    assert net["trips"]["a"]["predicted_j"] == pytest.approx(14.5)  # (12-1+18)*0.5
    assert net["trips"]["a"]["error"] == pytest.approx(14.5 / 12.5 - 1.0)
    assert net["max_abs_error"] == pytest.approx(14.5 / 12.5 - 1.0)
    assert net["mean_abs_error"] == pytest.approx((14.5 / 12.5 - 1.0) / 2)


def test_no_traction_trip_is_nan_and_left_out_of_summary():
    meas = np.array([-1.0, -2.0, 5.0])
    pred = np.array([1.0, -2.0, 10.0])
    out = trip_energy(pred, meas, 1.0, ["x", "x", "y"])
    assert np.isnan(out["trips"]["x"]["error"])
    assert out["mean_abs_error"] == pytest.approx(1.0)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(-5e4, 5e4), st.floats(-5e4, 5e4), st.integers(0, 3)),
                min_size=1, max_size=60))
def test_per_trip_energies_add_up_to_the_whole(rows):
    pred, meas, trip = (np.array(c) for c in zip(*rows))
    dt = 0.125
    out = trip_energy(pred, meas, dt, trip)
    tot_meas = sum(t["measured_j"] for t in out["trips"].values())
    assert tot_meas == pytest.approx(float(np.maximum(meas, 0).sum() * dt), abs=1e-6)
    net = trip_net_energy(pred, meas, dt, trip)
    assert sum(t["predicted_j"] for t in net["trips"].values()) == pytest.approx(
        float(pred.sum() * dt), abs=1e-6)


def test_report_json_carries_trip_energy_only_when_trips_known():
    n = 40
    v = np.linspace(5.0, 25.0, n)
    x = Inputs(v=v, a=np.zeros(n), theta=np.zeros(n), wind=np.zeros(n),
               mass=np.full(n, 1500.0), rho=np.full(n, 1.2))
    eq = Equation(name="aero_only", terms={"aero": 0.3})
    meas = 0.5 * 1.2 * 0.3 * v ** 3
    trip = np.repeat(["t1", "t2"], n // 2)
    doc = compare(meas, x, [eq], dt_s=0.5, trip=trip).to_json()
    te = doc["equations"]["aero_only"]["trip_energy"]
    assert set(te["trips"]) == {"t1", "t2"}
    assert te["max_abs_error"] >= 0.0
    assert "trip_net_energy" in doc["equations"]["aero_only"]
    json.dumps(doc)
    assert "trip_energy" not in compare(meas, x, [eq], dt_s=0.5).to_json()["equations"]["aero_only"]
    x.trip = trip  # the inputs carry the trips: used by default
    assert "trip_energy" in compare(meas, x, [eq], dt_s=0.5).to_json()["equations"]["aero_only"]


# ------------------------------------------------- trips that lost samples (left out)

def test_left_out_shares_by_trip_hand_computed():
    from sumo_drvpw.fit.trip_energy import left_out_by_trip, with_left_out

    # trip a: 4 samples of 1 s, P = 10, 10, 20, -5 W; the 20-W one is left out
    #   -> 1/4 of samples and time, 20/40 of traction energy, 20/35 of net energy
    # trip b: 2 samples of 2 s, the one left out has no measured power (NaN)
    meas = np.array([10.0, 10.0, 20.0, -5.0, 8.0, np.nan])
    used = np.array([True, True, False, True, True, False])
    dt = np.array([1.0, 1.0, 1.0, 1.0, 2.0, 2.0])
    left = left_out_by_trip(meas, used, dt, np.array(["a"] * 4 + ["b"] * 2))
    a, b = left["a"], left["b"]
    assert (a["samples"], a["left_out_samples"]) == (4, 1)
    assert a["left_out_time_share"] == pytest.approx(0.25)
    assert a["left_out_energy_share"] == pytest.approx(0.5)
    assert a["left_out_net_energy_share"] == pytest.approx(20.0 / 35.0)
    assert b["left_out_time_share"] == pytest.approx(0.5)
    assert b["left_out_energy_share"] == pytest.approx(0.0)  # known power: none left out
    assert b["left_out_power_unknown_samples"] == 1
    doc = trip_energy(meas[used], meas[used], dt[used], np.array(["a"] * 3 + ["b"]))
    out = with_left_out(doc, left)
    # a: 50 % of its energy; b: 50 % of its time with no measured power, energy unknown
    assert out["partial_trips"] == ["a", "b"]
    assert b["left_out_power_unknown_time_share"] == pytest.approx(0.5)
    assert out["trips"]["a"]["measured_j"] == pytest.approx(20.0)  # still the used samples (10 + 10)


def test_left_out_time_without_energy_is_not_partial():
    """Standstill left out (a tracer's minimum speed): time, but no measured energy lost."""
    from sumo_drvpw.fit.trip_energy import left_out_by_trip, with_left_out

    meas = np.array([0.0, 0.0, 0.0, 5000.0, 6000.0])  # 3 s standing, power measured: 0 W
    used = np.array([False, False, False, True, True])
    left = left_out_by_trip(meas, used, 1.0, None)
    assert left["0"]["left_out_time_share"] == pytest.approx(0.6)
    doc = with_left_out(trip_energy(meas[used], meas[used], 1.0, None), left)
    assert doc["partial_trips"] == [] and doc["trips"]["0"]["partial"] is False


def _log_with_a_gap(tmp_path):
    """Two 200-s trips at 1 Hz with logged power; trip a has 60 s flagged (brake),
    which the reader leaves out: 30 % of its time and (constant power) of its energy."""
    import pandas as pd

    rows = []
    for trip in ("a", "b"):
        t = np.arange(200.0)
        v = 10.0 + 5.0 * np.sin(t / 15.0)
        brake = (t >= 50) & (t < 110) if trip == "a" else np.zeros(200, bool)
        rows.append(pd.DataFrame({"trip_id": trip, "time_s": t, "speed_mps": v,
                                  "power_w": 8000.0 + 300.0 * v, "mass_kg": 1500.0, "brake": brake}))
    f = tmp_path / "gap.csv"
    pd.concat(rows).to_csv(f, index=False)
    return f


@pytest.mark.parametrize("engine", ["local", "memory"])
def test_compare_report_flags_a_trip_that_lost_samples(tmp_path, engine):
    from sumo_drvpw.cli import main as cli_main

    f = _log_with_a_gap(tmp_path)
    out = tmp_path / "cmp"
    assert cli_main(["compare", str(f), "--equation", "drvpw_prius3", "--engine", engine,
                     "--out", str(out)]) == 0
    doc = json.loads((out / "report.json").read_text(encoding="utf-8"))
    for key in ("trip_energy", "trip_net_energy"):
        te = doc["equations"]["drvpw_prius3"][key]
        a, b = te["trips"]["a"], te["trips"]["b"]
        assert a["left_out_samples"] == 60 and b["left_out_samples"] == 0
        assert a["left_out_time_share"] == pytest.approx(0.3, abs=0.01)
        assert 0.2 < a["left_out_energy_share"] < 0.4
        assert (a["partial"], b["partial"]) == (True, False)
        assert te["partial_trips"] == ["a"]
        assert {"measured_j", "predicted_j", "error"} <= set(a)  # the old keys stay
    md = (out / "report.md").read_text(encoding="utf-8")
    assert "**Partial trips**" in md and "a (30 % of time" in md


@pytest.mark.parametrize("stream", ["no", "yes"])
def test_diagnose_trace_flags_a_trip_that_lost_samples(tmp_path, stream):
    from sumo_drvpw.cli import main as cli_main

    f = _log_with_a_gap(tmp_path)
    out = tmp_path / "dg"
    assert cli_main(["diagnose", str(f), "--stream", stream, "--out", str(out)]) == 0
    doc = json.loads((out / "trace.json").read_text(encoding="utf-8"))
    for key in ("baseline", "final"):
        te = doc[key]["trip_energy"]
        assert te["partial_trips"] == ["a"]
        assert te["trips"]["a"]["left_out_time_share"] == pytest.approx(0.3, abs=0.01)
    rows = [ln for ln in (out / "trace.md").read_text(encoding="utf-8").splitlines() if ln.startswith("| a |")]
    assert rows and "partial: 30 % of time" in rows[0]


def test_chain_trace_flags_a_trip_that_lost_samples(tmp_path):
    """diagnose --target battery: the per-trip net energies of trace.json carry each trip's
    left-out shares and the partial flag, and trace.md's per-trip table says it (a 'left
    out' column and the Partial trips line), as the driving-power trace and compare do. A
    planted battery log whose trip T0 has 30 % of its samples flagged brake (left out)."""
    from sumo_drvpw.cli import main as cli_main
    from sumo_drvpw.model.equations import Equation, load_equation, save_equation
    from sumo_drvpw.synth.effects import BatteryLog, synth_trips
    from sumo_drvpw.synth.track import Noise

    b = BatteryLog(standstill_aux_w=0.0, noise_w=100.0)
    df, _ = synth_trips(n_trips=4, minutes=8.0, seed=5, effects=(b,), noise=Noise(process_w=50.0, process_rel=0.002))
    first = df["trip_id"].iloc[0]
    rows = np.flatnonzero((df["trip_id"] == first).to_numpy())
    df["brake"] = False
    df.loc[df.index[rows[int(0.4 * len(rows)):int(0.7 * len(rows))]], "brake"] = True
    log = tmp_path / "log.parquet"
    df.to_parquet(log)
    truth = load_equation("drvpw_prius3")
    decl = tmp_path / "declared.toml"
    save_equation(Equation("declared", dict(truth.terms), truth.mass_kg, chain=b.chain()), decl)
    out = tmp_path / "trace"
    assert cli_main(["diagnose", str(log), "--vehicle", "prius3", "--equation", str(decl), "--out", str(out),
                     "--quiet"]) == 0
    rep = json.loads((out / "trace.json").read_text(encoding="utf-8"))
    for key in ("baseline", "final"):
        te = rep[key]["trip_net_energy"]
        assert te["partial_trips"] == [str(first)]
        assert te["trips"][str(first)]["left_out_time_share"] == pytest.approx(0.3, abs=0.01)
        assert all(v["left_out_samples"] == 0 for t, v in te["trips"].items() if t != str(first))
        assert "fuel" not in te and all("measured_l" not in v for v in te["trips"].values())  # kWh: no litres
    md = (out / "trace.md").read_text(encoding="utf-8")
    row = [ln for ln in md.splitlines() if ln.startswith(f"| {first} |")]
    assert row and "partial: 30 % of time" in row[0] and "**Partial trips**" in md


def test_validation_trip_rows_carry_left_out_shares_and_the_tables_flag_partial_trips():
    """validate --chain: a per-trip row (validation/chain_common.trip_rows) says what the trip
    lost to samples left out (non-finite measured or predicted power) and whether that makes
    it partial; the report's per-trip tables (JLU, Prius, i3) name partial trips with the
    line compare's report.md has. A committed report without the keys renders as before."""
    from pathlib import Path

    from sumo_drvpw.validation.chain_common import trip_rows
    from sumo_drvpw.validation.chain_render import render

    n = 100
    trips = np.repeat(np.array(["a", "b"]), n)
    meas = np.full(2 * n, 2000.0)
    pred = np.full(2 * n, 2200.0)
    meas[20:50] = np.nan          # a: 30 % of its time without a measured power
    pred[n + 5:n + 10] = np.nan   # b: 5 % without a prediction (its energy share 5 %: not partial)
    rows = {r["trip"]: r for r in trip_rows(pred, meas, np.ones(2 * n), trips)}
    a, b = rows["a"], rows["b"]
    assert a["error"] == pytest.approx(0.1) and b["error"] == pytest.approx(0.1)
    assert a["left_out_power_unknown_time_share"] == pytest.approx(0.3) and a["partial"] is True
    assert b["left_out_energy_share"] == pytest.approx(0.05) and b["partial"] is False

    repo = Path(__file__).resolve().parents[1]
    doc = json.loads((repo / "docs" / "energy-chain-validation.json").read_text(encoding="utf-8"))

    def rows_of(d):  # every per-trip row of the report, wherever it sits
        if isinstance(d, dict):
            if "trip" in d:
                yield d
            for v in d.values():
                yield from rows_of(v)
        elif isinstance(d, list):
            for v in d:
                yield from rows_of(v)

    for r in rows_of(doc):  # a report written before the keys existed
        for k in [k for k in r if k.startswith("left_out_") or k == "partial"]:
            del r[k]
    md = render(doc, "cmd")
    assert "**Partial trips**" not in md  # rows without the keys: rendered as before
    for section, key in (("jlu", "before"), ("prius2", "rows"), ("bmw_i3", "rows")):
        row = doc[section][key][0]
        row.update({k: a[k] for k in a if k.startswith("left_out_")}, partial=True)
        flagged = render(doc, "cmd")
        assert flagged.count("**Partial trips**") == 1, section
        assert f"{row['trip']} (30 % of time" in flagged
        row["partial"] = False


# ------------------------------------------------- report.md: energy per trip, in the chain's unit

def _md_table(md: str, heading: str) -> dict:
    """The rows of the table under ``heading`` in report.md: first cell → the other cells."""
    lines = md.splitlines()
    i = lines.index(heading)
    i = next(j for j in range(i + 1, len(lines)) if lines[j].startswith("|"))  # the table's header
    rows = {}
    for ln in lines[i + 2:]:
        if not ln.startswith("|"):
            break
        cells = [c.strip() for c in ln.strip("|").split("|")]
        rows[cells[0]] = cells[1:]
    return rows


def _pct(cell: str) -> float:
    return float(cell.replace("−", "-").replace("%", "").strip()) / 100.0


def _trips_log(tmp_path, fuel=None):
    """Eleven trips (t1 … t11, so t10 sorts after t9 only in natural order) of stop-and-go
    driving at 2 Hz with a logged wheel power; trip t3 loses 30 % of its time to braking
    flags (partial); trip t11 is 8 s parked with a little power (small). ``fuel``: an
    equation file whose chain gives the logged fuel flow (± 4 % noise per sample)."""
    import pandas as pd

    rng = np.random.default_rng(7)
    rows = []
    for k in range(1, 12):
        t = np.arange(0.0, 16.0 if k == 11 else 120.0, 0.5)
        v = 12.0 + 6.0 * np.sin(2 * np.pi * t / 40.0 + k) + 2.0 * np.sin(2 * np.pi * t / 7.0)
        if k == 11:
            v = np.zeros_like(t)
        p = 1500.0 * v * np.gradient(v, t) + 150.0 * v + 0.4 * v ** 3 + (300.0 if k == 11 else 0.0)
        brake = (t >= 30) & (t < 66) if k == 3 else np.zeros(t.size, bool)
        rows.append(pd.DataFrame({"trip_id": f"t{k}", "time_s": t, "speed_mps": v, "power_w": p,
                                  "mass_kg": 1500.0, "brake": brake}))
    df = pd.concat(rows, ignore_index=True)
    if fuel is not None:
        from sumo_drvpw.data.log import from_frame
        from sumo_drvpw.model.constants import FUELS
        from sumo_drvpw.model.equations import load_equation

        ch = load_equation(fuel).chain
        pf = ch.evaluate(df["power_w"].to_numpy(), from_frame(df).inputs().v)["power_w"]
        df["fuel_rate_gps"] = pf / FUELS["gasoline"]["lhv_j_per_kg"] * 1e3 * (1 + 0.04 * rng.standard_normal(len(df)))
    f = tmp_path / "trips.csv"
    df.to_csv(f, index=False)
    return f


def _check_trip_tables(md: str, eq_docs: dict, heading: str, key: str, per_unit, unit_key=None):
    """Each trip's row of the table under ``heading``: measured and each equation's predicted
    energy equal report.json's J · ``per_unit`` to the decimals shown (and to its ``unit_key``
    value, litres, when given), the errors report.json's; trips in natural order; the last
    row the mean and worst |error| of report.json (small trips out)."""
    rows = _md_table(md, heading)
    names = list(eq_docs)
    first = eq_docs[names[0]][key]
    assert list(rows)[:-1] == sorted(first["trips"], key=lambda t: int(t[1:]))
    for t, cells in list(rows.items())[:-1]:
        meas = float(cells[0].replace("−", "-"))
        nd = len(cells[0].split(".")[1])
        assert meas == pytest.approx(first["trips"][t]["measured_j"] * per_unit, abs=0.51 * 10 ** -nd)
        if unit_key:
            assert meas == pytest.approx(first["trips"][t][f"measured_{unit_key}"], abs=0.51 * 10 ** -nd)
        for i, nm in enumerate(names):
            x = eq_docs[nm][key]["trips"][t]
            assert float(cells[1 + 2 * i].replace("−", "-")) == pytest.approx(x["predicted_j"] * per_unit,
                                                                           abs=0.51 * 10 ** -nd)
            if unit_key:
                assert float(cells[1 + 2 * i].replace("−", "-")) == pytest.approx(x[f"predicted_{unit_key}"],
                                                                               abs=0.51 * 10 ** -nd)
            assert _pct(cells[2 + 2 * i]) == pytest.approx(x["error"], abs=0.0005)
    last = rows["mean / worst abs. error"]
    for i, nm in enumerate(names):
        d = eq_docs[nm][key]
        mean, worst = last[2 + 2 * i].split(" (")[0].split(" / ")
        assert _pct(mean) == pytest.approx(d["mean_abs_error"], abs=0.0005)
        assert _pct(worst) == pytest.approx(d["max_abs_error"], abs=0.0005)
    return rows


@pytest.mark.parametrize("engine", ["memory", "local"])
def test_compare_report_md_has_energy_per_trip_in_kwh(tmp_path, engine):
    """compare's report.md: a section "Energy per trip" whose traction and net tables give,
    per trip, the measured and each equation's predicted energy in kWh = report.json's
    J / 3.6e6, the error and the mean / worst |error| as report.json has them (the small
    parked trip left out of those and marked, the partial trip marked), trips sorted."""
    from sumo_drvpw.cli import main as cli_main

    out = tmp_path / "cmp"
    assert cli_main(["compare", str(_trips_log(tmp_path)), "--equation", "drvpw_prius3", "--equation",
                     "vsp_ldv1999", "--engine", engine, "--out", str(out)]) == 0
    doc = json.loads((out / "report.json").read_text(encoding="utf-8"))
    md = (out / "report.md").read_text(encoding="utf-8")
    assert "## Energy per trip" in md
    eqs = doc["equations"]
    assert eqs["drvpw_prius3"]["trip_energy"]["small_trips"] == ["t11"]
    assert eqs["drvpw_prius3"]["trip_energy"]["partial_trips"] == ["t3"]
    for heading, key in (("### Traction energy [kWh]", "trip_energy"), ("### Net energy [kWh]", "trip_net_energy")):
        rows = _check_trip_tables(md, eqs, heading, key, 1 / 3.6e6)
        assert rows["t11"][-1].startswith("small") and "partial: 30 % of time" in rows["t3"][-1]
        assert rows["t1"][-1] == ""


def _fuel_eq(tmp_path, name, fuel, v3):
    f = tmp_path / f"{name}.toml"
    f.write_text(f'[equation]\nname = "{name}"\n[terms]\nacc = 1.0\nv1 = 150.0\nv3 = {v3}\n[chain]\n'
                 'predicts = "fuel"\ntraction_efficiency = 0.9\naux_power_w = 300.0\nidle_fuel_power_w = 3000.0\n'
                 f'marginal_efficiency = 0.33\nengine_off_below_w = 0.0\nfuel = "{fuel}"\n', encoding="utf-8")
    return f


@pytest.mark.parametrize("engine", ["memory", "local"])
def test_compare_report_gives_a_fuel_chain_trip_energy_in_litres(tmp_path, engine):
    """compare --target fuel: report.json's per-trip energies carry litres too (measured_l,
    predicted_l = J / (LHV · density) of the chain's fuel: petrol 43.2 MJ/kg · 0.745 kg/L =
    32.184 MJ/L, diesel 43.1 · 0.832 = 35.859 MJ/L, JEC WTW v5), and report.md's per-trip
    tables give them, headed with the fuel; the errors are the J's. A petrol and a diesel
    chain: one table each."""
    from sumo_drvpw.cli import main as cli_main

    ice, dsl = _fuel_eq(tmp_path, "ice", "gasoline", 0.42), _fuel_eq(tmp_path, "dsl", "diesel", 0.38)
    out = tmp_path / "cmp"
    assert cli_main(["compare", str(_trips_log(tmp_path, fuel=ice)), "--equation", str(ice), "--equation", str(dsl),
                     "--target", "fuel", "--engine", engine, "--out", str(out)]) == 0
    doc = json.loads((out / "report.json").read_text(encoding="utf-8"))
    md = (out / "report.md").read_text(encoding="utf-8")
    assert doc["settings"]["target"] == "fuel"
    for nm, per_l in (("ice", 43.2e6 * 0.745), ("dsl", 43.1e6 * 0.832)):
        for key in ("trip_energy", "trip_net_energy"):
            te = doc["equations"][nm][key]
            assert te["fuel_j_per_l"] == pytest.approx(per_l, rel=1e-12)
            for x in te["trips"].values():
                assert x["measured_l"] == pytest.approx(x["measured_j"] / per_l, rel=1e-12)
                assert x["predicted_l"] == pytest.approx(x["predicted_j"] / per_l, rel=1e-12)
        fuel = doc["equations"][nm]["chain"]["fuel"]
        # fuel power is never negative here: traction and net are one table
        heading = f"### Traction and net energy [L of {fuel}] (equal here: no sample has negative power)"
        _check_trip_tables(md, {nm: doc["equations"][nm]}, heading, "trip_energy", 1 / per_l, unit_key="l")
    assert "32.18 MJ per litre" in md and "35.86 MJ per litre" in md


def test_chain_trace_md_gives_a_fuel_target_in_litres(tmp_path):
    """diagnose --target fuel: trace.md's per-trip table is in litres of the chain's fuel
    (trace.json's J / 32.184 MJ/L), as compare's report.md (one helper: report/format.py
    energy_unit)."""
    from sumo_drvpw.cli import main as cli_main

    ice = _fuel_eq(tmp_path, "ice", "gasoline", 0.42)
    out = tmp_path / "trace"
    assert cli_main(["diagnose", str(_trips_log(tmp_path, fuel=ice)), "--equation", str(ice), "--target", "fuel",
                     "--out", str(out), "--quiet"]) == 0
    rep = json.loads((out / "trace.json").read_text(encoding="utf-8"))
    md = (out / "trace.md").read_text(encoding="utf-8")
    assert "| trip | measured L | before L |" in md and "Litres of gasoline" in md
    rows = _md_table(md, "## Before and after, per trip (net energy; after = held out)")
    per_l = 43.2e6 * 0.745
    for t, x in rep["baseline"]["trip_net_energy"]["trips"].items():
        assert float(rows[t][0]) == pytest.approx(x["measured_j"] / per_l, abs=5.1e-4)
        assert float(rows[t][1]) == pytest.approx(x["predicted_j"] / per_l, abs=5.1e-4)


def test_many_trips_show_the_worst_and_say_how_many_are_left_out():
    """A report of 250 trips: each table shows the 200 with the largest |error|, in trip
    order, and says that 50 are omitted and report.json has every trip. A report.json
    written before ``settings.target`` existed renders too (kWh for a wheel target)."""
    from sumo_drvpw.fit.trip_energy import trip_energy, trip_net_energy
    from sumo_drvpw.report.comparison import MAX_TRIP_ROWS, trip_energy_lines

    n = 250
    rng = np.random.default_rng(3)
    trip = np.repeat([f"x{i}" for i in range(n)], 10)
    meas = rng.uniform(-5e3, 2e4, trip.size)  # with recuperation: traction and net differ
    pred = meas * np.repeat(1.0 + rng.normal(0.0, 0.05, n), 10)
    doc = {"equations": {"eq": {"trip_energy": trip_energy(pred, meas, 1.0, trip),
                                "trip_net_energy": trip_net_energy(pred, meas, 1.0, trip)}},
           "settings": {}}
    md = "\n".join(trip_energy_lines(doc))
    assert f"The {MAX_TRIP_ROWS} trips with the largest |error| of {n}; {n - MAX_TRIP_ROWS} omitted " \
           "(report.json has every trip)." in md
    rows = _md_table(md, "### Traction energy [kWh]")
    shown = list(rows)[:-1]
    assert len(shown) == MAX_TRIP_ROWS and shown == sorted(shown, key=lambda t: int(t[1:]))
    err = {t: abs(v["error"]) for t, v in doc["equations"]["eq"]["trip_energy"]["trips"].items()}
    assert min(err[t] for t in shown) >= max(err[t] for t in err if t not in shown)


# ------------------------------------------------- a fuel target's litres elsewhere (follow-ups)

def _share_rows(md: str) -> tuple[list, dict]:
    """The energy-share table of report.md: its header cells and its rows (name → cells)."""
    lines = md.splitlines()
    i = next(j for j in range(lines.index("## Energy share of each term (cf. paper Fig. 10)"), len(lines))
             if lines[j].startswith("|"))
    head = [c.strip() for c in lines[i].strip("|").split("|")]
    rows = {}
    for ln in lines[i + 2:]:
        if not ln.startswith("|"):
            break
        cells = [c.strip() for c in ln.strip("|").split("|")]
        rows[cells[0]] = dict(zip(head[1:], cells[1:]))
    return head, rows


@pytest.mark.parametrize("engine", ["memory", "local"])
def test_energy_share_table_gives_a_fuel_target_in_litres(tmp_path, engine):
    """compare --target fuel: the energy-share table's predicted and measured traction are
    litres of the chain's fuel, report.json's J / (LHV · density) (petrol 32.184 MJ/L), its
    header says so; a wheel target keeps kWh (J / 3.6e6)."""
    from sumo_drvpw.cli import main as cli_main

    ice = _fuel_eq(tmp_path, "ice", "gasoline", 0.42)
    log = _trips_log(tmp_path, fuel=ice)
    out = tmp_path / "cmp"
    assert cli_main(["compare", str(log), "--equation", str(ice), "--target", "fuel", "--engine", engine,
                     "--out", str(out)]) == 0
    doc = json.loads((out / "report.json").read_text(encoding="utf-8"))
    head, rows = _share_rows((out / "report.md").read_text(encoding="utf-8"))
    assert "Predicted traction [L of gasoline]" in head and "Measured traction [L of gasoline]" in head
    d, per_l = doc["equations"]["ice"], 43.2e6 * 0.745
    row = rows["ice"]
    assert float(row["Predicted traction [L of gasoline]"]) == pytest.approx(d["predicted_traction_energy_j"] / per_l,
                                                                             abs=5.1e-4)
    assert float(row["Measured traction [L of gasoline]"]) == pytest.approx(doc["measured"]["traction_energy_j"]
                                                                            / per_l, abs=5.1e-4)
    out2 = tmp_path / "wheel"
    assert cli_main(["compare", str(log), "--equation", "drvpw_prius3", "--engine", engine, "--out", str(out2)]) == 0
    doc2 = json.loads((out2 / "report.json").read_text(encoding="utf-8"))
    head2, rows2 = _share_rows((out2 / "report.md").read_text(encoding="utf-8"))
    assert float(rows2["drvpw_prius3"]["Predicted traction [kWh]"]) == pytest.approx(
        doc2["equations"]["drvpw_prius3"]["predicted_traction_energy_j"] / 3.6e6, abs=5.1e-4)


def test_chain_trace_json_gives_a_fuel_target_in_litres(tmp_path):
    """diagnose --target fuel: trace.json's per-trip net energies (baseline and final) carry
    litres of the chain's fuel too, measured_l / predicted_l = J / 32.184 MJ/L (petrol), the
    document's fuel and fuel_j_per_l, as compare's report.json; the J keys stay, and trace.md's
    litres are these (a battery target's get none: test_chain_trace_flags_a_trip_that_lost_samples)."""
    from sumo_drvpw.cli import main as cli_main

    ice = _fuel_eq(tmp_path, "ice", "gasoline", 0.42)
    out = tmp_path / "trace"
    assert cli_main(["diagnose", str(_trips_log(tmp_path, fuel=ice)), "--equation", str(ice), "--target", "fuel",
                     "--out", str(out), "--quiet"]) == 0
    rep = json.loads((out / "trace.json").read_text(encoding="utf-8"))
    rows = _md_table((out / "trace.md").read_text(encoding="utf-8"), "## Before and after, per trip (net energy; after = held out)")
    per_l = 43.2e6 * 0.745
    for key in ("baseline", "final"):
        te = rep[key]["trip_net_energy"]
        assert te["fuel"] == "gasoline" and te["fuel_j_per_l"] == pytest.approx(per_l, rel=1e-12)
        for t, x in te["trips"].items():
            assert x["measured_l"] == pytest.approx(x["measured_j"] / per_l, rel=1e-12)
            assert x["predicted_l"] == pytest.approx(x["predicted_j"] / per_l, rel=1e-12)
            cell = rows[t][1] if key == "baseline" else rows[t][3]
            assert float(cell) == pytest.approx(x["predicted_l"], abs=5.1e-4)
            assert float(rows[t][0]) == pytest.approx(x["measured_l"], abs=5.1e-4)


@pytest.mark.parametrize("engine", ["memory", "local"])
def test_compare_says_when_the_chain_burns_another_fuel_than_the_log_was_read_as(tmp_path, engine):
    """compare --target fuel reads the log's fuel flow as the vehicle file's powertrain.fuel
    (else the one fuel the compared chains burn, else gasoline) and gives litres of each
    chain's fuel: when they differ, report.json (settings.fuel_note, with
    settings.measured_fuel) and report.md's summary say so in one line naming both fuels and
    the chain; when they agree, no note. Without a vehicle file and with a diesel chain the
    flow is read as diesel (before: as gasoline, with the note): its measured energy is the
    gasoline reading's × 43.1/43.2 (the fuels' LHV per kg; the log's flow is in g/s)."""
    from sumo_drvpw.cli import main as cli_main

    ice, dsl = _fuel_eq(tmp_path, "ice", "gasoline", 0.42), _fuel_eq(tmp_path, "dsl", "diesel", 0.38)
    log = _trips_log(tmp_path, fuel=ice)
    car = tmp_path / "car.toml"
    car.write_text('[vehicle]\nname = "car"\nmass_kg = 1500\n[powertrain]\nfuel = "diesel"\n', encoding="utf-8")
    runs = {"vehicle diesel, chain gasoline": (["--vehicle", str(car), "--equation", str(ice)], "diesel", "ice"),
            "no vehicle, chain diesel": (["--equation", str(dsl)], "diesel", None),
            "agree": (["--equation", str(ice)], "gasoline", None)}
    measured = {}
    for i, (args, read_as, odd) in enumerate(runs.values()):
        out = tmp_path / f"cmp{i}"
        assert cli_main(["compare", str(log), *args, "--target", "fuel", "--engine", engine, "--out", str(out)]) == 0
        doc = json.loads((out / "report.json").read_text(encoding="utf-8"))
        s, md = doc["settings"], (out / "report.md").read_text(encoding="utf-8")
        assert s["measured_fuel"] == read_as
        measured[i] = next(iter(doc["equations"].values()))["trip_net_energy"]["trips"]
        if odd is None:
            assert "fuel_note" not in s and "was read as" not in md
            continue
        note = s["fuel_note"]
        burns = "gasoline" if read_as == "diesel" else "diesel"
        assert f"read as {read_as}" in note and f"{odd} burns {burns}" in note and "\n" not in note
        summary = md.split("## Summary")[1].split("\n## ")[0]
        assert summary.count(note) == 1
    for trip, d in measured[1].items():  # read as diesel against as gasoline
        assert d["measured_j"] == pytest.approx(measured[2][trip]["measured_j"] * 43.1 / 43.2, rel=1e-9)


def test_chain_trace_says_when_the_chain_burns_another_fuel_than_the_log_was_read_as(tmp_path):
    """diagnose --target fuel with a vehicle file naming gasoline and a diesel chain:
    trace.json's fuel_note (with measured_fuel) and one line of trace.md say so, as
    compare's report; a gasoline chain: no note. Without a vehicle file the flow is read as
    the chain's fuel (diesel), and no note."""
    from sumo_drvpw.cli import main as cli_main

    ice, dsl = _fuel_eq(tmp_path, "ice", "gasoline", 0.42), _fuel_eq(tmp_path, "dsl", "diesel", 0.38)
    log = _trips_log(tmp_path, fuel=ice)
    car = tmp_path / "petrol_car.toml"
    car.write_text('[vehicle]\nname = "petrol_car"\nmass_kg = 1500\n[powertrain]\nfuel = "gasoline"\n', encoding="utf-8")
    for eq, note, veh, read_as in ((dsl, True, ["--vehicle", str(car)], "gasoline"), (ice, False, [], "gasoline"),
                                   (dsl, False, [], "diesel")):
        out = tmp_path / f"trace_{eq.stem}_{len(veh)}"
        assert cli_main(["diagnose", str(log), "--equation", str(eq), *veh, "--target", "fuel", "--out", str(out),
                         "--quiet"]) == 0
        rep = json.loads((out / "trace.json").read_text(encoding="utf-8"))
        md = (out / "trace.md").read_text(encoding="utf-8")
        assert rep["measured_fuel"] == read_as
        if note:
            assert "read as gasoline" in rep["fuel_note"] and "dsl burns diesel" in rep["fuel_note"]
            assert md.count(rep["fuel_note"]) == 1
        else:
            assert "fuel_note" not in rep and "was read as" not in md


def test_net_energy_error_of_a_descent_below_zero_is_the_miss_over_traction():
    """fit.trip_energy.net_energy_errors' rule (its docstring): the relative net-energy error
    only where the measured net energy is at least NET_SHARE_MIN of the measured traction
    energy, a signed comparison. A descent that recuperates more than it drove has a negative
    net energy however large |net| is, so it gets the miss as a share of its traction energy.
    By hand: 10 s at +10 kW, 10 s at −15 kW measured (traction 100 kJ, net −50 kJ,
    |net| = 0.5 × traction); predicted recuperation 2 kW weaker (−13 kW): net −30 kJ, the miss
    +20 kJ → 20 kJ / 100 kJ = 0.2, not the relative error −30/−50 − 1 = −0.4."""
    from sumo_drvpw.fit.trip_energy import NET_SHARE_MIN, net_energy_errors

    meas = np.array([10e3] * 10 + [-15e3] * 10)
    pred = np.array([10e3] * 10 + [-13e3] * 10)
    trip = np.array(["descent"] * 20)
    assert abs(-50e3) >= NET_SHARE_MIN * 100e3  # |net| is no small denominator: only its sign sends it
    e = net_energy_errors(pred, meas, 1.0, trip)
    assert e["descent"] == pytest.approx(20e3 / 100e3)
