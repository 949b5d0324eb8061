"""A plug-in hybrid's charge-depleting start (model/chain_plugin.py, ``[chain.depleting]``):
on its battery until the declared usable energy is spent, then the charge-sustaining hybrid's
fuel; by hand, through the file, and in a real SUMO run, live and replayed from its FCD."""

from __future__ import annotations

import numpy as np
import pytest

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.chain_toml import chain_from_dict

ETA_M = 0.4
DOC = {"predicts": "fuel", "fuel": "gasoline", "marginal_efficiency": ETA_M, "idle_fuel_power_w": 5000.0,
       "engine_off_below_w": 8000.0, "charge_sustaining": True, "aux_power_w": 500.0,
       "recuperation_round_trip": 0.64, "recuperation_limit_w": 30000.0}
DEP = {"usable_j": 1.0e6, "traction_efficiency": 0.8, "recuperation_efficiency": 0.6}


def _chain(**dep):
    return chain_from_dict({**DOC, "depleting": {**DEP, **dep}}, "phev.toml")


def test_on_the_battery_until_its_usable_energy_is_spent_then_on_fuel():
    """+20 kW: 20/0.8 + 0.5 = 25.5 kW from the battery, 1 MJ lasts 39.2 s: 39 whole seconds on
    the battery (no fuel), 0.216 of the 40th, then the charge-sustaining chain's fuel. A braking
    second on the battery gives 0.6 × 10 kW back (less the 0.5-kW auxiliaries): it lasts longer."""
    p = np.full(60, 20e3)
    out = _chain().evaluate(p, np.full(60, 15.0), 1.0)
    cs = chain_from_dict(DOC).evaluate(p, np.full(60, 15.0), 1.0)
    np.testing.assert_allclose(out["battery_j"][:39], 25.5e3)
    share = (1e6 - 39 * 25.5e3) / 25.5e3
    assert out["battery_j"][39] == pytest.approx(share * 25.5e3)
    assert out["battery_j"].sum() == pytest.approx(1e6) and np.all(out["battery_j"][40:] == 0.0)
    assert np.all(out["fuel_l"][:39] == 0.0) and not out["engine_on"][:39].any()
    assert out["fuel_l"][39] == pytest.approx((1 - share) * cs["fuel_l"][39])
    np.testing.assert_array_equal(out["fuel_l"][40:], cs["fuel_l"][40:])
    assert out["spent_j"][-1] == 1e6
    # a braking second while on the battery: it gives 0.6 × 10 kW − 0.5 kW back
    q = np.r_[np.full(10, 20e3), -10e3, np.full(50, 20e3)]
    back = _chain().evaluate(q, 15.0, 1.0)
    assert back["battery_w"][10] == pytest.approx(-0.6 * 10e3 + 500.0)
    assert back["battery_j"].sum() == pytest.approx(1e6)
    assert back["fuel_l"].sum() < out["fuel_l"].sum() and back["fuel_l"][10] == 0.0


def test_trips_start_charged_and_vehicles_carry_their_own_battery():
    rng = np.random.default_rng(5)
    p = rng.normal(8e3, 20e3, 400)
    dt = rng.uniform(0.2, 1.0, p.size)
    trip = np.repeat([0, 1], 200)
    ch = _chain(usable_j=2e6)
    two = ch.evaluate(p, 12.0, dt, trip=trip)
    np.testing.assert_allclose(two["power_w"][200:], ch.evaluate(p[200:], 12.0, dt[200:])["power_w"])
    one = ch.evaluate(p, 12.0, dt)
    before = np.r_[0.0, one["spent_j"][:-1]]
    step = ch.evaluate(p, 12.0, dt, spent_j=before)
    for k in ("power_w", "battery_w", "spent_j"):
        np.testing.assert_allclose(step[k], one[k])
    # energy: what the battery gave less what it took is what was spent (a full battery takes no more)
    assert one["spent_j"].max() <= 2e6 and one["battery_j"].sum() == pytest.approx(one["spent_j"][-1])
    assert one["spent_j"][-1] == 2e6 and one["fuel_l"][-50:].sum() > 0


def test_a_rated_output_is_asked_beyond_only_while_the_engine_runs():
    """A plug-in with an engine cap (engine_max_w) driving on its battery asks its engine for
    nothing: no over_engine demand while the battery carries the car (share 1), (1 − share) of the
    charge-sustaining chain's on the sample it runs out, all of it once spent."""
    cap = {"engine_max_w": 30e3}
    p = np.full(60, 40e3)
    ch = chain_from_dict({**DOC, **cap, "depleting": DEP}, "phev.toml")
    cs = chain_from_dict({**DOC, **cap}).evaluate(p, 15.0, 1.0)
    out = ch.evaluate(p, 15.0, 1.0)
    assert cs["over_engine_w"][0] > 0
    k = int(np.flatnonzero(out["battery_w"] < out["battery_w"][0])[0])   # the sample the battery runs out
    share = out["battery_w"][k] / out["battery_w"][0]
    assert 0 < share < 1 and np.all(out["battery_w"][k + 1:] == 0)
    assert np.all(out["over_engine_w"][:k] == 0.0) and np.all(out["over_engine_j"][:k] == 0.0)
    assert out["over_engine_w"][k] == pytest.approx((1 - share) * cs["over_engine_w"][k])
    np.testing.assert_array_equal(out["over_engine_w"][k + 1:], cs["over_engine_w"][k + 1:])


def test_the_file_keeps_it_and_refuses_what_is_no_plug_in():
    ch = _chain()
    assert chain_from_dict(ch.to_dict()) == ch and ch.to_dict()["depleting"]["usable_j"] == 1e6
    plain = {k: x for k, x in DOC.items() if k != "recuperation_round_trip"}
    for doc, says in [({**plain, "charge_sustaining": False, "depleting": DEP}, "charge_sustaining = true"),
                      ({**DOC, "depleting": {"traction_efficiency": 0.8}}, "'usable_j'"),
                      ({**DOC, "depleting": {**DEP, "usable_j": 0.0}}, "must be > 0"),
                      ({**DOC, "depleting": {**DEP, "soc": 1}}, "unknown key"),
                      ({**DOC, "depleting": {"usable_j": 1e6, "traction_efficiency": 0.8}},
                       "'recuperation_efficiency' required"),
                      ({**DOC, "depleting": {"usable_j": 1e6}}, "'traction_efficiency' and 'recuperation_efficiency'")]:
        with pytest.raises(UserError, match=r"phev\.toml \[chain\.depleting\]") as e:
            chain_from_dict(doc, "phev.toml")
        assert says in str(e.value)
    with pytest.raises(UserError, match=r"phev\.toml \[chain\]: 'depleting\.usable_j' = 8 J .*not kWh or Wh"):
        chain_from_dict({**DOC, "depleting": {**DEP, "usable_j": 8}}, "phev.toml")   # 8 kWh written as J
    with pytest.raises(UserError, match="duration"):
        _chain().evaluate(np.array([1e4]), 5.0)


@pytest.mark.parametrize("key, value", [("aux_power_w", -5.0), ("aux_power_w", "300 W"),
                                        ("hvac", {"column": 42}), ("loads", {"heater_w": -1.0})])
def test_a_bad_key_of_the_chain_the_battery_inherits_is_blamed_on_the_chain(key, value):
    """aux_power_w, loads and hvac are the fuel chain's, which [chain.depleting] inherits: an error
    in them names [chain] (or [chain.hvac], [chain.loads]), not [chain.depleting], where the key is not."""
    with pytest.raises(UserError, match=r"phev\.toml \[chain[.\]]") as e:
        chain_from_dict({**DOC, key: value, "depleting": DEP}, "phev.toml")
    assert "depleting" not in str(e.value)


def test_a_calibration_refuses_a_declared_plug_in_battery_it_would_drop():
    from types import SimpleNamespace

    from sumo_drvpw.fit.chain import declared_fuel_cut

    plain = {k: x for k, x in DOC.items() if k != "recuperation_round_trip"}
    assert declared_fuel_cut(SimpleNamespace(chain=chain_from_dict({**plain, "fuel_cut_below_w": 0.0}))) == 0.0
    with pytest.raises(UserError, match=r"phev\.toml \[chain\.depleting\].*not fitted"):
        declared_fuel_cut(SimpleNamespace(chain=chain_from_dict({**plain, "depleting": DEP}, "phev.toml")))


@pytest.mark.sumo
def test_a_plug_in_hybrid_in_sumo_books_its_battery_then_fuel_live_and_replayed(tmp_path):
    """A real SUMO run: a plug-in hybrid (HBEFA 4's PC_PHEV_petrol class) drives 5.5 km at up to
    22 m/s with 300 kJ usable: chain_vehicles.csv books its battery (net 300 kJ: spent, then
    charge-sustaining) and fuel for the rest, less than the same car without the plug-in's
    battery; the replay of the run's FCD books the same, the battery carried per vehicle."""
    pytest.importorskip("libsumo")
    import shutil

    import pandas as pd
    from sumo_probe import build_net
    from test_chain_battery_window import run_and_replay, write_equation

    build_net(tmp_path, '<nodes><node id="a" x="0" y="0"/><node id="b" x="5500" y="0"/></nodes>',
              '<edges><edge id="ab" from="a" to="b" numLanes="1" speed="22"/></edges>', "--no-warnings")
    (tmp_path / "r.rou.xml").write_text(
        '<routes><vType id="h" vClass="passenger" mass="1500" sigma="0" '
        'emissionClass="HBEFA4/PC_PHEV_petrol_Euro-6d_(P)"/>'
        '<vehicle id="v" type="h" depart="0"><route edges="ab"/></vehicle></routes>', encoding="utf-8")
    run_and_replay(tmp_path, [write_equation(tmp_path / "phev.toml", "phev", DOC, {"depleting": {**DEP, "usable_j": 3e5}})])
    # the same car without the plug-in's battery, in a run of its own (where both chains are named, the
    # plug-in hybrid's class is booked by the plug-in chain alone: sim/powertrain.py)
    hev = tmp_path / "hev"
    hev.mkdir()
    for f in ("n.net.xml", "r.rou.xml"):
        shutil.copy(tmp_path / f, hev / f)
    run_and_replay(hev, [write_equation(hev / "hev.toml", "hev", DOC)])
    rows = {out: pd.read_csv(tmp_path / out / "chain_vehicles.csv", dtype={"key": str}).set_index("equation")
            for out in ("o", "r")}
    o = pd.concat([rows["o"], pd.read_csv(hev / "o" / "chain_vehicles.csv", dtype={"key": str}).set_index("equation")])
    assert o.loc["phev", "net_kwh"] == pytest.approx(3e5 / 3.6e6, rel=1e-9)   # all of it spent, no more
    assert np.isnan(o.loc["hev", "net_kwh"])
    assert 0 < o.loc["phev", "fuel_l"] < o.loc["hev", "fuel_l"]
    for col in ("fuel_l", "net_kwh", "traction_kwh"):
        assert rows["r"].loc["phev", col] == pytest.approx(o.loc["phev", col], rel=1e-6)
    edges = pd.read_csv(tmp_path / "o" / "chain_edges.csv").set_index("equation")
    assert edges.loc["phev", "net_kwh"].sum() == pytest.approx(o.loc["phev", "net_kwh"], rel=1e-9)


def test_the_trace_columns_of_a_capped_plug_in_sum_to_its_fuel():
    """fit/chain_linear.linearised_columns of a plug-in with a rated output (40 kW) over four
    generated 1000-s trips: Σ columns + offset is its fuel on every sample but those whose share on
    the battery ±1 W changes, around where a trip spends its last joule (nonlinear) — also where it drives
    on its battery beyond the rating, which burns nothing (before: the rating's fuel booked there,
    40 kW/0.4 on each of 53 samples, 1.47 kWh of the 23.8 kWh predicted)."""
    from sumo_drvpw.fit.chain_linear import linearised_columns, predict
    from sumo_drvpw.model.chain_plugin import fuel_share
    from sumo_drvpw.model.equations import Equation
    from sumo_drvpw.model.terms import Inputs

    rng = np.random.default_rng(1)
    n = 4000
    v = np.abs(rng.normal(15, 8, n))
    v[:300] = 0.0
    trip = np.repeat(np.arange(4), n // 4)
    x = Inputs(v, rng.normal(0, 0.6, n), rng.normal(0, 0.04, n), np.zeros(n), np.full(n, 1800.0), np.full(n, 1.2),
               trip=trip)
    dt, cap = np.ones(n), 40000.0
    plain = {k: x for k, x in DOC.items() if not k.startswith("recuperation")}  # (braking beyond a limit: no column's)
    ch = chain_from_dict({**plain, "engine_max_w": cap, "moving_idle_fuel_power_w": 9000.0,
                          "depleting": {**DEP, "usable_j": 2.0e6}})
    eq = Equation("e", {"acc": 1.0, "aero": 0.6, "roll": 0.008, "grade": 1.0}, chain=ch)
    cols, off = linearised_columns(eq, x, dt)
    p = eq.power(x)
    spent = ch.evaluate(p, v, dt, None, trip)["spent_j"]
    # where ±1 W on every sample moves the battery's last joule (the regime changes: no linear column)
    moved = fuel_share(ch, p + 1.0, v, dt, None, trip) != fuel_share(ch, p - 1.0, v, dt, None, trip)
    assert 4 <= moved.sum() <= 12
    over_on_battery = (spent < 2.0e6) & (p / 1.0 + DOC["aux_power_w"] >= cap)
    assert over_on_battery.sum() > 20
    np.testing.assert_allclose((sum(cols.values()) + off)[~moved], predict(eq, x, None, dt)[~moved], rtol=1e-9, atol=1e-6)
