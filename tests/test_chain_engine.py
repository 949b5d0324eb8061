"""A heavy engine's fuel chain (model/chain.py): the fuel at zero output while moving apart from
the standing idle fuel (``moving_idle_fuel_power_w``: a diesel's friction grows with engine
speed) and the engine's rated output (``engine_max_w``: a demand above it cannot be delivered),
read, written, evaluated and recovered by calibration (fit/chain_fuel.py) on a planted truck.

Why: two measured class-8 trucks (UC Riverside's VT data) burned 99 kW of fuel below 30 kW at
the wheels where the chain booked its 49 kW idle, and 726 kW above 300 kW where the uncapped
line booked 1,135 kW."""

from __future__ import annotations

import numpy as np
import pytest

from sumo_drvpw.errors import UserError
from sumo_drvpw.fit.chain_fuel import calibrate_fuel
from sumo_drvpw.model.chain_toml import chain_from_dict

IDLE_W, MOVING_W, ETA, CAP_W = 8_000.0, 30_000.0, 0.40, 300_000.0
TRUCK = {"predicts": "fuel", "fuel": "diesel", "marginal_efficiency": ETA, "idle_fuel_power_w": IDLE_W,
         "engine_off_below_w": -np.inf}


def _truck(seed=3, dt=1.0):
    """Trips of a 30 t truck at 1 Hz — accelerate, cruise on hills, brake, stand 60 s — and the
    fuel a planted engine burns (:data:`MOVING_W` while moving at zero output, capped at
    :data:`CAP_W`), with 3 % noise: speed, driving power, fuel power."""
    rng = np.random.default_rng(seed)
    v = []
    for _ in range(40):
        top = rng.uniform(8.0, 27.0)
        up = np.arange(0.0, top, rng.uniform(0.2, 0.6) * dt)
        v += [up, np.full(int(rng.uniform(60, 400) / dt), top), np.arange(top, 0.0, -rng.uniform(0.5, 1.5) * dt),
              np.zeros(int(60 / dt))]
    v = np.concatenate(v)
    grade = 0.04 * np.sin(np.arange(v.size) / 150.0)
    a = np.gradient(v, dt)
    p = 30_000 * (a * v + 9.81 * grade * v) + 1800 * v + 4.0 * v ** 3
    ch = chain_from_dict({**TRUCK, "moving_idle_fuel_power_w": MOVING_W, "engine_max_w": CAP_W})
    fuel = ch.evaluate(p, v)["power_w"] * (1 + 0.03 * rng.standard_normal(v.size))
    return v, p, fuel


def test_defaults_keep_todays_chain_and_file():
    """Without the keys the chain books the idle fuel moving too, has no cap and writes neither."""
    ch = chain_from_dict(dict(TRUCK))
    assert ch.moving_idle_fuel_power_w is None and ch.engine_max_w is None
    assert not {"moving_idle_fuel_power_w", "engine_max_w"} & set(ch.to_dict())
    out = ch.evaluate(np.array([0.0, 0.0, 1e6]), np.array([0.0, 20.0, 20.0]))
    np.testing.assert_allclose(out["power_w"], [IDLE_W, IDLE_W, IDLE_W + 1e6 / ETA])
    assert "over_engine_w" not in out


def test_moving_idle_and_cap_evaluate_and_round_trip():
    """Standing: the idle fuel; moving at zero output: the moving one; above the cap: fuel at the
    cap, the rest of the demand counted as over_engine (hand calculation)."""
    ch = chain_from_dict({**TRUCK, "moving_idle_fuel_power_w": MOVING_W, "engine_max_w": CAP_W})
    out = ch.evaluate(np.array([0.0, 0.0, 100e3, 500e3]), np.array([0.0, 20.0, 20.0, 20.0]), dt_s=2.0)
    np.testing.assert_allclose(out["power_w"], [IDLE_W, MOVING_W, MOVING_W + 100e3 / ETA, MOVING_W + CAP_W / ETA])
    np.testing.assert_allclose(out["over_engine_w"], [0, 0, 0, 200e3])
    np.testing.assert_allclose(out["over_engine_j"], [0, 0, 0, 400e3])
    assert chain_from_dict(ch.to_dict()) == ch


@pytest.mark.parametrize("doc, key", [
    ({**TRUCK, "moving_idle_fuel_power_w": IDLE_W - 1}, "moving_idle_fuel_power_w"),
    ({**TRUCK, "engine_max_w": 0}, "engine_max_w"),
    ({**TRUCK, "engine_max_w": -5}, "engine_max_w"),
    ({**TRUCK, "engine_max_w": 300}, r"engine_max_w.*watts, not kW.*got 300"),   # a 300-kW engine in kW
    ({"predicts": "battery", "engine_max_w": 1e5}, "engine_max_w"),
    ({"predicts": "battery", "moving_idle_fuel_power_w": 1e4}, "moving_idle_fuel_power_w")])
def test_bad_engine_keys_are_one_line_naming_the_key(doc, key):
    with pytest.raises(UserError, match=key) as e:
        chain_from_dict(doc, "truck.toml")
    assert "truck.toml" in str(e.value) and "\n" not in str(e.value)


def test_planted_moving_idle_and_cap_are_recovered():
    """A calibration with both recovers the planted idle, moving zero-output fuel, η_m and rated
    output within 2 %; without them its one zero-output fuel is far from the idle fuel."""
    v, p, fuel = _truck()
    assert (p > CAP_W).mean() > 0.02  # the planted data reach the cap
    fit = calibrate_fuel(p, v, fuel, 1.0, fuel="diesel", engine_off=-np.inf, engine_on_above_mps=None,
                         moving_idle=True, engine_max_w="profile")
    ch = fit.chain
    for got, want in ((ch.idle_fuel_power_w, IDLE_W), (ch.moving_idle_fuel_power_w, MOVING_W),
                      (ch.marginal_efficiency, ETA), (ch.engine_max_w, CAP_W)):
        assert got == pytest.approx(want, rel=0.02)
    assert fit.parameters["engine_max_w"]["how"].startswith("profiled")
    plain = calibrate_fuel(p, v, fuel, 1.0, fuel="diesel", engine_off=-np.inf, engine_on_above_mps=None).chain
    assert plain.idle_fuel_power_w > 2 * IDLE_W and plain.engine_max_w is None  # one intercept: not the idle


def test_no_cap_where_the_engine_is_never_at_it():
    """A cap is kept only where the fit says so (BIC): a planted engine below its rating has none."""
    v, p, _ = _truck()
    ch = chain_from_dict({**TRUCK, "moving_idle_fuel_power_w": MOVING_W})
    fuel = ch.evaluate(p, v)["power_w"] * (1 + 0.03 * np.random.default_rng(1).standard_normal(v.size))
    fit = calibrate_fuel(p, v, fuel, 1.0, fuel="diesel", engine_off=-np.inf, engine_on_above_mps=None,
                         moving_idle=True, engine_max_w="profile")
    assert fit.chain.engine_max_w is None
    assert fit.chain.moving_idle_fuel_power_w == pytest.approx(MOVING_W, rel=0.02)


def test_a_declared_rating_is_kept_at_the_wheels():
    """The calibrated chain has η_t 1 and no separate auxiliaries: a rated output declared with
    η_t 0.8 and 10 kW of accessories is kept where P/η_t + P_aux reaches it, (300 − 10)·0.8 kW."""
    from sumo_drvpw.fit.chain_fuel import declared_engine
    from sumo_drvpw.model.equations import Equation

    decl = chain_from_dict({"predicts": "fuel", "engine_max_w": CAP_W, "traction_efficiency": 0.8, "aux_power_w": 1e4})
    kw = declared_engine(Equation("e", {"v1": 1.0}, chain=decl))
    assert kw == {"moving_idle": False, "engine_max_w": pytest.approx((CAP_W - 1e4) * 0.8)}


@pytest.mark.parametrize("engine", ["memory", "local"])
def test_calibrate_fits_the_moving_idle_an_equation_declares(tmp_path, capsys, engine):
    """`calibrate --target fuel --equation FILE` whose chain declares a moving zero-output fuel
    fits it (≥ idle) and keeps a declared rated output, in memory and streamed alike (the two
    equal to 1e-9: tests/test_chain_engine_stream.py)."""
    import tomllib

    import pandas as pd

    from sumo_drvpw.cli import main as cli_main

    rng = np.random.default_rng(7)
    v = np.concatenate([np.concatenate([np.linspace(0, top, 40), np.full(200, top), np.linspace(top, 0, 30),
                                        np.zeros(60)]) for top in rng.uniform(8, 25, 25)])
    t = np.arange(v.size, dtype=float)
    p = 1500 * np.gradient(v, t) * v + 150 * v + 0.4 * v ** 3
    ch = chain_from_dict({"predicts": "fuel", "fuel": "gasoline", "marginal_efficiency": 0.35, "idle_fuel_power_w": 4000.0,
                          "engine_off_below_w": -np.inf, "moving_idle_fuel_power_w": 9000.0})
    fuel_w = ch.evaluate(p, v)["power_w"] + rng.normal(0, 200.0, v.size)
    pd.DataFrame({"time_s": t, "speed_mps": v, "fuel_rate_lph": fuel_w / (43.2e6 * 0.745) * 3600.0,
                  "mass_kg": 1500.0}).to_parquet(tmp_path / "log.parquet")
    (tmp_path / "rl.toml").write_text('[equation]\nname = "rl"\n[terms]\nv1 = 150.0\nv3 = 0.4\nacc = 1.0\n'
                                      '[chain]\npredicts = "fuel"\nmoving_idle_fuel_power_w = 0.0\n'
                                      'engine_max_w = 200000.0\n', encoding="utf-8")
    out = tmp_path / "o.toml"
    rc = cli_main(["calibrate", str(tmp_path / "log.parquet"), "--target", "fuel", "--equation",
                   str(tmp_path / "rl.toml"), "--engine", engine, "--out", str(out)])
    assert rc == 0, capsys.readouterr().err
    got = tomllib.loads(out.read_text(encoding="utf-8"))["chain"]
    assert got["engine_max_w"] == 200000.0
    assert got["idle_fuel_power_w"] == pytest.approx(4000.0, rel=0.05)
    assert got["moving_idle_fuel_power_w"] == pytest.approx(9000.0, rel=0.05)


def test_a_run_counts_and_says_the_demand_beyond_the_engine():
    """The SUMO ledger books a capped truck's fuel at its rated output, counts the vehicle-steps and
    energy asked beyond it, and says so (summary.json chain.engine_over_rated, a warning); a run
    whose chains have no cap keeps its summary and warnings as before."""
    from sumo_drvpw.sim.chain import ChainLedger
    from sumo_drvpw.sim.chain_outputs import chain_summary, chain_warnings

    capped = chain_from_dict({**TRUCK, "engine_max_w": CAP_W, "traction_efficiency": 0.8})
    p = np.array([[400e3 * 0.8], [100e3 * 0.8]])  # engine output 400 kW (100 beyond), 100 kW
    led = ChainLedger(["truck"], [capped], 1)
    for _ in range(10):
        led.book(np.arange(2), np.zeros(2, np.int64), np.full(2, 20.0), 1.0, p)
    assert led.over_engine[0].tolist() == [10, pytest.approx(100e3 * 10)]
    tot = led.vehicle_totals(2)
    assert tot[0, 0, 4] == pytest.approx(10 * (IDLE_W + CAP_W / ETA))  # fuel at the cap
    summ = chain_summary(led, ["a", "b"], ["trailer", "trailer"])
    assert summ["engine_over_rated"] == {"truck": {"vehicle_steps": 10, "kwh": pytest.approx(1e6 / 3.6e6)}}
    (w,) = [w for w in chain_warnings(led) if "rated output" in w]
    assert w.startswith("truck: 10 vehicle-steps") and "300 kW" in w and "0.278 kWh" in w
    plain = ChainLedger(["truck"], [chain_from_dict(dict(TRUCK))], 1)
    plain.book(np.arange(2), np.zeros(2, np.int64), np.full(2, 20.0), 1.0, p)
    assert "engine_over_rated" not in chain_summary(plain, ["a", "b"], ["trailer", "trailer"])
    assert not [w for w in chain_warnings(plain) if "rated output" in w]


def test_diagnose_finds_a_planted_moving_zero_output_fuel():
    """The chain trace on a fuel target offers the moving zero-output fuel: a conventional engine
    burning 6 kW standing and 9.5 kW at zero output while moving is found (≈ 3.5 kW above the idle)
    and written into the chain; with nothing planted, it is not found."""
    from sumo_drvpw.data.log import from_frame
    from sumo_drvpw.data.measured import measure
    from sumo_drvpw.fit.chain_linear import trace_chain
    from sumo_drvpw.model.chain import EnergyChain
    from sumo_drvpw.model.constants import FUELS
    from sumo_drvpw.model.equations import Equation, load_equation
    from sumo_drvpw.model.vehicles import load_vehicle
    from sumo_drvpw.synth.effects import BatteryLog, synth_trips
    from sumo_drvpw.synth.track import Noise

    df, _ = synth_trips(n_trips=6, minutes=10.0, seed=3, effects=(BatteryLog(standstill_aux_w=0.0, noise_w=100.0),),
                        noise=Noise(process_w=50.0, process_rel=0.002))
    veh, truth = load_vehicle("prius3"), load_equation("drvpw_prius3")
    x0 = measure(from_frame(df, veh, name="synth"), veh, "battery")
    p, v = truth.power(x0.inputs), x0.inputs.v
    assert 0.02 < np.mean(v < 0.1) < 0.95  # stands and moves
    rng = np.random.default_rng(8)
    lhv = FUELS["gasoline"]["lhv_j_per_kg"]
    declared = EnergyChain("fuel", 1.0, idle_fuel_power_w=6000.0, marginal_efficiency=0.33, engine_off_below_w=-np.inf)
    found = {}
    for moving in (None, 9500.0):
        ch = EnergyChain("fuel", 1.0, idle_fuel_power_w=6000.0, marginal_efficiency=0.33, engine_off_below_w=-np.inf,
                         moving_idle_fuel_power_w=moving)
        pf = ch.evaluate(p, v)["power_w"] * (1.0 + rng.normal(0, 0.03, p.size)).clip(0.0)
        d = df.drop(columns=["battery_voltage_v", "battery_current_a"]).assign(fuel_rate_gps=pf / lhv * 1000.0)
        m = measure(from_frame(d, veh, name="synth-fuel"), veh, "fuel")
        res = trace_chain(m, Equation("declared", dict(truth.terms), truth.mass_kg, chain=declared))
        found[moving] = ({f["term"]: f["coefficient"] for f in res.report["findings"]}, res.equation)
    assert "moving_idle_fuel_power_w" not in found[None][0]
    assert list(found[9500.0][0]) == ["moving_idle_fuel_power_w"]
    assert found[9500.0][1].chain.moving_idle_fuel_power_w == pytest.approx(9500.0, rel=0.05)


@pytest.mark.parametrize("keys", [{"moving_idle_fuel_power_w": MOVING_W}, {"engine_max_w": CAP_W},
                                  {"moving_idle_fuel_power_w": MOVING_W, "engine_max_w": CAP_W,
                                   "running_fuel_per_k": 0.003}])
def test_the_chain_trace_linearises_the_heavy_engine_exactly(keys):
    """The trace's columns (fit/chain_linear.py) sum to the chain's prediction with a moving
    zero-output fuel and a rated output (the demand beyond it changes nothing: gain 0)."""
    from sumo_drvpw.fit.chain_linear import gains, linearised_columns, predict
    from sumo_drvpw.model.equations import Equation
    from sumo_drvpw.model.terms import Inputs

    rng = np.random.default_rng(1)
    n = 4000
    v = np.abs(rng.normal(15, 8, n))
    v[:300] = 0.0
    x = Inputs(v, rng.normal(0, 0.6, n), rng.normal(0, 0.04, n), np.zeros(n), np.full(n, 30000.0),
               np.full(n, 1.2), signals={"ambient_c": rng.normal(10, 8, n)})
    ch = chain_from_dict({**TRUCK, "traction_efficiency": 0.8, "aux_power_w": 10000.0, "fuel_cut_below_w": 0.0, **keys})
    eq = Equation("e", {"acc": 1.0, "aero": 3.0, "roll": 0.006, "grade": 1.0}, chain=ch)
    cols, off = linearised_columns(eq, x)
    np.testing.assert_allclose(sum(cols.values()) + off, predict(eq, x), rtol=1e-12, atol=1e-6)
    if "engine_max_w" in keys:
        p = eq.power(x)
        beyond = p * 1.0 / 0.8 + 10000.0 > CAP_W
        assert beyond.mean() > 0.05 and np.all(gains(ch, p, v, x.signals)[0][beyond] == 0)


def test_dask_buckets_add_up_the_demand_beyond_the_engine():
    """An FCD replay on Dask books vehicles in buckets whose ledgers merge_ledgers adds: the
    counts of demand beyond a rated output (and of SUMO's MMPEVEM nan steps) are the buckets'
    sums, not the first bucket's."""
    from sumo_drvpw.sim.chain import ChainLedger
    from sumo_drvpw.sim.fcd_dask import merge_ledgers
    from sumo_drvpw.sim.ledger import Ledger

    capped = chain_from_dict({**TRUCK, "engine_max_w": CAP_W})
    leds = []
    for steps in (3, 5):
        led = Ledger(3, 1)
        led.chain = ChainLedger(["truck"], [capped], 3)
        for _ in range(steps):
            led.chain.book(np.arange(1), np.zeros(1, np.int64), np.full(1, 20.0), 1.0, np.array([[CAP_W + 1e5]]))
        led.chain.motor_invalid[0] = steps
        leds.append(led)
    out = merge_ledgers(leds).chain
    assert out.over_engine[0].tolist() == [8, pytest.approx(8e5)]
    assert out.motor_invalid.tolist() == [8]
