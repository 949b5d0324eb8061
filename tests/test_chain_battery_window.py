"""A charge-sustaining hybrid's usable battery window (model/chain_buffer.py, ``[chain]
battery_usable_j``): its braking energy is credited only while the battery has room, the
room comes back only as traction spends what is stored; unbounded (no key) books as before.
By hand, through ``compare`` per trip, and in a real SUMO run down a hill, live and replayed
from its FCD."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.chain_toml import chain_from_dict

ETA_T, ETA_M, RT, LIM = 0.9, 0.4, 0.64, 50000.0   # √η_rt = 0.8 each way
DOC = {"predicts": "fuel", "fuel": "gasoline", "marginal_efficiency": ETA_M, "idle_fuel_power_w": 0.0,
       "engine_off_below_w": 5000.0, "charge_sustaining": True, "recuperation_round_trip": RT,
       "recuperation_limit_w": LIM, "traction_efficiency": ETA_T}
W = 100e3   # J: the usable window


def _chain(**kw):
    return chain_from_dict({**DOC, **kw}, "h.toml")


def test_a_descent_fills_the_window_and_a_climb_empties_it():
    """−20 kW for 10 s: 0.8 × 20 kJ = 16 kJ offered a second; the 100-kJ window takes six
    whole seconds and 4 kJ of the seventh, nothing after; each stored joule is credited as the
    0.8 J it gives back at the wheels, through η_t and η_m. Then +10 kW: the battery gives back
    10 kJ a second at the wheels, 12.5 kJ of stored energy: empty after 8 s, when a second
    descent is credited again."""
    p = np.r_[np.full(10, -20e3), np.full(10, 10e3), np.full(2, -20e3)]
    out = _chain(battery_usable_j=W).evaluate(p, np.full(p.size, 10.0), 1.0)
    acc = np.r_[np.full(6, 16e3), 4e3, np.zeros(3)]
    np.testing.assert_allclose(out["given_back_j"][:10], 0.8 * acc)
    np.testing.assert_allclose(out["stored_j"][:10], np.minimum(np.cumsum(acc), W))
    np.testing.assert_allclose(out["stored_j"][10:20], np.maximum(W - 12.5e3 * np.arange(1, 11), 0.0))
    np.testing.assert_allclose(out["given_back_j"][20:], [12.8e3, 12.8e3])
    credit = -out["given_back_w"] / ETA_T / ETA_M
    paid = np.maximum(p, 0.0) / ETA_T / ETA_M           # (idle fuel 0, no auxiliaries)
    np.testing.assert_allclose(out["power_w"], paid + credit)
    unb = _chain().evaluate(p, np.full(p.size, 10.0), 1.0)
    # unbounded: all 200 kJ of the descent credited at 0.64; bounded: 80 kJ at the wheels
    assert -unb["power_j"][:10].sum() * ETA_T * ETA_M == pytest.approx(RT * 200e3)
    assert -out["power_j"][:10].sum() * ETA_T * ETA_M == pytest.approx(0.8 * W)


def test_no_window_is_the_unbounded_credit_to_the_bit_and_a_large_one_the_same():
    rng = np.random.default_rng(3)
    p = rng.normal(0.0, 30e3, 500)
    v = np.full(p.size, 12.0)
    old = _chain().evaluate(p, v)["power_w"]
    want = np.maximum(p, 0.0) / ETA_T / ETA_M \
        + RT * np.maximum(np.minimum(p, 0.0), -LIM) / ETA_T / ETA_M
    np.testing.assert_array_equal(old, want)
    assert "stored_j" not in _chain().evaluate(p, v, 1.0)
    big = _chain(battery_usable_j=1e9).evaluate(p, v, 1.0)
    np.testing.assert_allclose(big["power_w"], old, rtol=1e-12, atol=1e-6)
    assert _chain().to_dict().get("battery_usable_j") is None
    ch = _chain(battery_usable_j=W)
    assert chain_from_dict(ch.to_dict()) == ch and ch.to_dict()["battery_usable_j"] == W


def test_energy_is_conserved_and_trips_and_vehicles_carry_their_own_battery():
    """Σ stored ≤ W + Σ spent over any series; a new trip starts empty; one step of
    independent vehicles, each from its own stored energy, is the series stepped one at a time."""
    rng = np.random.default_rng(7)
    p = rng.normal(-2000.0, 40e3, 2000)
    dt = rng.uniform(0.1, 1.0, p.size)
    out = _chain(battery_usable_j=W).evaluate(p, np.full(p.size, 9.0), dt)
    stored_in = out["given_back_j"] / 0.8
    s = np.r_[0.0, out["stored_j"]]
    spent = np.maximum(s[:-1] - s[1:], 0.0)
    assert out["stored_j"].min() >= 0.0 and out["stored_j"].max() <= W * (1 + 1e-12)
    assert stored_in.sum() <= W + spent.sum() + 1e-6
    assert stored_in.sum() == pytest.approx(s[-1] + spent.sum())
    # spent only while driving, at most what gives min(P, P_lim)·Δt back at the wheels
    assert np.all(spent[p <= 0] == 0.0)
    assert np.all(spent <= np.minimum(np.maximum(p, 0.0), LIM) * dt / 0.8 + 1e-9)
    # two trips: the second starts empty
    trip = np.r_[np.zeros(1000), np.ones(1000)]
    two = _chain(battery_usable_j=W).evaluate(p, 9.0, dt, trip=trip)
    second = _chain(battery_usable_j=W).evaluate(p[1000:], 9.0, dt[1000:])
    np.testing.assert_allclose(two["power_w"][1000:], second["power_w"])
    np.testing.assert_array_equal(two["power_w"][:1000], out["power_w"][:1000])
    # a step of vehicles: sample i from the state the series had before it
    step = _chain(battery_usable_j=W).evaluate(p, 9.0, dt, stored_j=s[:-1])
    np.testing.assert_allclose(step["power_w"], out["power_w"])
    np.testing.assert_allclose(step["stored_j"], out["stored_j"])


@pytest.mark.parametrize("doc, says", [
    ({**DOC, "recuperation_round_trip": 0.0, "battery_usable_j": W}, "recuperation_round_trip > 0"),
    ({k: x for k, x in DOC.items() if k != "recuperation_round_trip"} | {"battery_usable_j": W},
     "recuperation_round_trip > 0"),
    ({**DOC, "battery_usable_j": -1.0}, "must be ≥ 0"),
    ({**DOC, "battery_usable_j": 0.5}, "not kWh or Wh (0.5 kWh = 1.8e+06 J)"),   # a Prius's 0.5 kWh
    ({**DOC, "battery_usable_j": 500}, "not kWh or Wh"),                       # … in Wh
])
def test_a_window_without_a_round_trip_is_refused(doc, says):
    with pytest.raises(UserError, match="battery_usable_j") as e:
        chain_from_dict(doc, "h.toml")
    assert says in str(e.value) and "h.toml" in str(e.value)


def test_a_window_of_zero_or_of_a_mild_hybrid_is_taken():
    """0 is a window that holds nothing (no credit); 10 kJ and up, joules of a battery."""
    for w in (0.0, 1e4, 1.8e6):
        assert _chain(battery_usable_j=w).battery_usable_j == w


def test_without_durations_a_window_says_so():
    with pytest.raises(UserError, match="h.toml.*battery_usable_j.*duration"):
        _chain(battery_usable_j=W).evaluate(np.array([-1e4]), np.array([5.0]))


def test_compare_carries_the_window_through_each_trip():
    """``compare`` on a fuel target: the chain's prediction is the series per trip (two trips
    of one descent each: both credited up to the window, not the second left without room)."""
    from sumo_drvpw.fit.compare import compare
    from sumo_drvpw.model.equations import Equation
    from sumo_drvpw.model.terms import Inputs

    n = 40
    v = np.full(2 * n, 10.0)
    a = np.zeros(2 * n)
    theta = np.full(2 * n, -0.1)   # downhill: m·g·v·sin θ ≈ −14.6 kW at 1500 kg
    x = Inputs(v=v, a=a, theta=theta, wind=np.zeros(2 * n), mass=np.full(2 * n, 1500.0),
               rho=np.full(2 * n, 1.2), trip=np.repeat(["t1", "t2"], n))
    eq = Equation("h", {"grade": 1.0}, chain=_chain(battery_usable_j=W))
    cmp = compare(np.zeros(2 * n), x, [eq], dt_s=1.0, target="fuel")
    pred = cmp.results["h"].pred_w
    p = 1500.0 * 9.81 * 10.0 * math.sin(-0.1)
    assert p == pytest.approx(eq.power(x)[0], rel=1e-3)
    for t in (slice(0, n), slice(n, 2 * n)):   # each trip: its window's 0.8 × W back at the wheels
        assert -pred[t].sum() * ETA_T * ETA_M == pytest.approx(0.8 * W)


def write_equation(path, name: str, chain: dict, sub: dict | None = None) -> str:
    """An equation file at ``path``: the SUMO tests' road load and ``chain`` as its [chain]
    (``sub``: its sub-tables, name → table); returns the file's name."""
    def val(x):
        return str(x).lower() if isinstance(x, bool) else repr(x).replace("'", '"')

    lines = [f'[equation]\nname = "{name}"\nvclasses = ["passenger"]\n[terms]\nacc = 1.0\ngrade = 1.0\n'
             'roll = 0.008\naero_rho = 0.6\n[chain]'] + [f"{k} = {val(x)}" for k, x in chain.items()]
    for t, d in (sub or {}).items():
        lines += [f"[chain.{t}]"] + [f"{k} = {val(x)}" for k, x in d.items()]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path.name


def run_and_replay(tmp_path, files: list[str]) -> None:
    """The equation ``files`` on ``n.net.xml`` and ``r.rou.xml`` in ``tmp_path``: run live into
    ``o`` (with SUMO's FCD) and replayed from that FCD into ``r``."""
    from sumo_drvpw.cli import main as cli_main
    from sumo_drvpw.sim.run import run_scenario

    (tmp_path / "s.toml").write_text(f'equations = {files!r}\n'.replace("'", '"')
                                     + '[sumo]\nnet = "n.net.xml"\nroutes = ["r.rou.xml"]\nend = 600\n'
                                     'step_length = 1.0\noptions = ["--no-warnings", "true", "--fcd-output", "fcd.xml"]\n'
                                     '[outputs]\nfigures = false\n', encoding="utf-8")
    run_scenario(tmp_path / "s.toml", tmp_path / "o")
    assert cli_main(["fcd", str(tmp_path / "o" / "sumo" / "fcd.xml"), "--scenario", str(tmp_path / "s.toml"),
                     "--out", str(tmp_path / "r")]) == 0


@pytest.mark.sumo
def test_a_hybrid_down_a_hill_in_sumo_books_only_its_window_live_and_replayed(tmp_path):
    """A real SUMO run: a hybrid car (HBEFA 4's plug-in petrol class, booked as a full hybrid)
    rolls 4 km down a 5 % hill (200 m) at 22 m/s, braking ~9 kW, then 1.5 km on the flat.
    Unbounded, the descent is credited over a MJ at the wheels (negative litres no hybrid
    battery could take); with a 100-kJ window, 0.8 × what it stored: the window, and more only
    as far as the flat's traction spent it (conservation). Replayed from the run's FCD, the
    same: the battery is carried per vehicle from step to step in both."""
    pytest.importorskip("libsumo")
    import pandas as pd
    from sumo_probe import build_net

    build_net(tmp_path, '<nodes><node id="a" x="0" y="0" z="200"/><node id="b" x="4000" y="0" z="0"/>'
              '<node id="c" x="5500" y="0" z="0"/></nodes>',
              '<edges><edge id="ab" from="a" to="b" numLanes="1" speed="22"/>'
              '<edge id="bc" from="b" to="c" numLanes="1" speed="22"/></edges>', "--no-warnings")
    (tmp_path / "r.rou.xml").write_text(
        '<routes><vType id="h" vClass="passenger" mass="1500" sigma="0" '
        'emissionClass="HBEFA4/PC_PHEV_petrol_Euro-6d_(P)"/>'
        '<vehicle id="v" type="h" depart="0" departSpeed="max"><route edges="ab bc"/></vehicle></routes>',
        encoding="utf-8")
    chains = {"none": {k: x for k, x in DOC.items() if k != "recuperation_round_trip"}, "unbounded": DOC,
              "window": {**DOC, "battery_usable_j": W}}
    run_and_replay(tmp_path, [write_equation(tmp_path / f"{n}.toml", n, c) for n, c in chains.items()])
    books = {}
    for out in ("o", "r"):
        rows = pd.read_csv(tmp_path / out / "chain_vehicles.csv", dtype={"key": str}).set_index("equation")
        fuel = (rows["fuel_kwh"] * 3.6e6).to_dict()
        veh = pd.read_parquet(tmp_path / out / "vehicles.parquet").set_index("equation")
        traction = float(veh.loc["window", "traction_total_j"])   # at the wheels, all of the trip
        # credit at the wheels: the fuel the round trip takes off, back through η_t and η_m
        credit = {k: (fuel["none"] - fuel[k]) * ETA_T * ETA_M for k in ("unbounded", "window")}
        assert credit["unbounded"] > 1e6                       # over a MJ down 200 m
        assert fuel["unbounded"] < 0 < fuel["window"] < fuel["none"]   # unbounded: a trip of negative litres
        assert credit["window"] >= 0.8 * W * (1 - 1e-9)        # the window filled on the descent
        assert credit["window"] <= 0.8 * W + traction + 1e-6   # and no more than the flat spent of it
        assert credit["window"] < 0.3 * credit["unbounded"]
        books[out] = (fuel, credit)
    for k in chains:   # live and replayed alike
        assert books["r"][0][k] == pytest.approx(books["o"][0][k], rel=1e-6)


def test_compare_streamed_and_in_memory_carry_the_window_through_each_trip_alike(tmp_path):
    """``compare --target fuel`` on a log of two trips (speed swinging ±9 m/s: a braking every
    few minutes; each trip ends braking, its battery full), streamed in batches of whole trips
    (the default) and in memory: each trip's predicted fuel the same to 1e-9 — the second, which
    brakes from its start, starts with an empty battery in both —, and the window's more than
    the unbounded chain's."""
    import json

    import corpus
    import pandas as pd

    from sumo_drvpw.cli import main as cli_main
    from sumo_drvpw.data.log import from_frame
    from sumo_drvpw.model.chain import EnergyChain
    from sumo_drvpw.model.equations import load_equation

    df = corpus.sine_trips(np.random.default_rng(5), 3400, 12.0)   # 680 s: decelerating for the last 67 s
    t = np.arange(200) * 0.2   # T2: braking from 20 m/s to rest at 0.5 m/s², from its start
    df = pd.concat([df[df.trip_id == "T1"], pd.DataFrame({"trip_id": "T2", "time_s": t, "speed_mps": 20.0 - 0.5 * t,
                                                          "mass_kg": 1400.0})], ignore_index=True)
    p = load_equation(corpus.road_equation(tmp_path)).power(from_frame(df).inputs())
    plant = EnergyChain(predicts="fuel", idle_fuel_power_w=8000.0, marginal_efficiency=0.35, engine_off_below_w=-np.inf)
    df["fuel_flow_rate_hour_lph"] = plant.evaluate(p, df["speed_mps"].to_numpy())["fuel_lps"] * 3600.0
    log = tmp_path / "fuel.csv"
    df.to_csv(log, index=False)
    eqs = [write_equation(tmp_path / "w.toml", "w", {**DOC, "battery_usable_j": 20e3}),
           write_equation(tmp_path / "u.toml", "u", DOC)]
    pred = {}
    for engine in ([], ["--engine", "memory"]):
        out = tmp_path / f"c{len(engine)}"
        assert cli_main(["compare", str(log), "--target", "fuel", "--out", str(out)]
                        + [a for e in eqs for a in ("--equation", str(tmp_path / e))] + engine) == 0
        rep = json.loads((out / "report.json").read_text(encoding="utf-8"))["equations"]
        pred[len(engine)] = {n: {t: r["predicted_j"] for t, r in rep[n]["trip_net_energy"]["trips"].items()}
                             for n in ("w", "u")}
    for n in ("w", "u"):
        assert set(pred[0][n]) == {"T1", "T2"}
        for t in ("T1", "T2"):
            assert pred[0][n][t] == pytest.approx(pred[2][n][t], rel=1e-9)
    for t in ("T1", "T2"):
        assert pred[0]["w"][t] > pred[0]["u"][t] * 1.01
