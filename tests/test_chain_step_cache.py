"""The chain booking's per-step overhead at a few vehicles a step (sim/chain.py, model/chain.py):
what does not change between steps is built once per ledger, work the step does not need is
not done, and what is booked is the same as the plain computation (benchmarks/run_ratio.py
measures the run; no timing here)."""

from __future__ import annotations

import numpy as np

from sumo_drvpw.model.chain import EnergyChain, Table
from sumo_drvpw.model.constants import FUELS
from sumo_drvpw.sim.chain import ChainLedger


def _fuel(**kw) -> EnergyChain:
    return EnergyChain(**{"predicts": "fuel", "idle_fuel_power_w": 4000.0, "marginal_efficiency": 0.35,
                          "engine_off_below_w": 0.0, **kw})


def test_a_step_of_one_vehicle_per_edge_needs_no_unique(monkeypatch):
    """np.unique (a sort, an inverse and more: a tenth of a step's booking at five vehicles)
    runs only in a step where two vehicles share an edge; the edge totals are the per-edge
    sums of the step's quantities either way."""
    led = ChainLedger(["f"], [_fuel()], 100)
    calls, real = [], np.unique

    def spy(*a, **kw):
        calls.append(1)
        return real(*a, **kw)

    monkeypatch.setattr(np, "unique", spy)
    rng, want = np.random.default_rng(5), np.zeros((100, 1, 8))
    for k in range(30):
        eidx = rng.permutation(100)[:4] if k % 2 else np.array([3, 3, 50, 3])
        before = len(calls)
        full = led.expand(led.book(np.arange(4), eidx, rng.uniform(0, 20, 4), 1.0, rng.normal(0, 2e4, (4, 1))))
        assert len(calls) == before + (0 if k % 2 else 1), k
        for q in range(8):
            want[:, 0, q] += np.bincount(eidx, full[:, 0, q], minlength=100)
    np.testing.assert_allclose(led.edge, want, rtol=1e-12, atol=0.0)


def test_constant_signals_are_built_once_and_read_the_run_values(monkeypatch):
    """The chains' constant signals (the run's air temperature, a load given as a constant, a
    load not given: 0) are the same read-only arrays from step to step at any number of
    vehicles, each step's first n of them; the booked quantities are those of the chains
    evaluated on freshly built constants."""
    fuel = _fuel(running_fuel_per_k=0.01)
    bat = EnergyChain(predicts="battery", aux_power_w=300.0, loads={"heater_w": 1.0, "fan_w": 0.5},
                      hvac={"column": "ambient_c", "setpoint_c": 21.0, "heating_w_per_k": 150.0,
                            "cooling_w_per_k": 50.0})
    led = ChainLedger(["f", "b"], [fuel, bat], 10, signal_values={"ambient_c": 5.0, "heater_w": 800.0})
    seen, real = [], EnergyChain.evaluate

    def spy(self, p, v, dt=None, signals=None, *a, **kw):
        seen.append(signals)
        return real(self, p, v, dt, signals, *a, **kw)

    monkeypatch.setattr(EnergyChain, "evaluate", spy)
    rng = np.random.default_rng(2)
    for n in (3, 5, 2, 70, 4):
        p, v = rng.normal(0, 2e4, (n, 2)), rng.uniform(0, 20, n)
        q = led.book(np.arange(n), np.arange(n) % 10, v, 1.0, p)
        sig = {"ambient_c": np.full(n, 5.0), "heater_w": np.full(n, 800.0), "fan_w": np.zeros(n)}
        np.testing.assert_array_equal(q[:, :4], np.stack([real(fuel, p[:, 0], v, 1.0, sig)[k]
                                                           for k in ("power_j", "fuel_l", "co2_kg")]
                                                          + [np.zeros(n)], axis=1))
        np.testing.assert_array_equal(q[:, 4:], np.stack([real(bat, p[:, 1], v, 1.0, sig)[k] for k in
                                                          ("traction_j", "recuperated_j", "auxiliary_j",
                                                           "power_j")], axis=1))
    assert led.assumed_zero == {"fan_w"}
    steps = seen[::2]  # (both chains read one step's dict)
    for s in steps:
        assert set(s) == {"ambient_c", "heater_w", "fan_w"}
        assert not any(x.flags.writeable for x in s.values())
    for i, j in ((1, 2), (3, 4)):  # a step of no more vehicles than an earlier one: that step's arrays
        assert all(np.shares_memory(steps[i][k], steps[j][k]) for k in steps[i]), (i, j)


def test_a_fuel_chain_evaluates_its_engine_state_and_efficiency_table_once(monkeypatch):
    """A fuel chain's step evaluates whether the engine runs once (what it pays for is that, or
    everything for a charge-sustaining hybrid) and its η_t table once, also where a hybrid's
    braking energy is given back; the fuel power is the module's Willans line by hand."""
    eta = Table(values=np.array([0.8, 0.9, 0.92]), speed_mps=np.array([0.0, 10.0, 30.0]))
    counts = {"eta": 0, "on": 0}
    real_call, real_on = Table.__call__, EnergyChain.engine_on

    def call(self, v, p):
        counts["eta"] += 1
        return real_call(self, v, p)

    def on(self, p, v):
        counts["on"] += 1
        return real_on(self, p, v)

    monkeypatch.setattr(Table, "__call__", call)
    monkeypatch.setattr(EnergyChain, "engine_on", on)
    p = np.array([-30000.0, -5000.0, 0.0, 2000.0, 9000.0, 40000.0])
    v = np.array([12.0, 3.0, 0.0, 5.0, 15.0, 25.0])
    for cs, rt in ((False, 0.0), (True, 0.64)):
        ch = _fuel(traction_efficiency=eta, aux_power_w=500.0, engine_off_below_w=8000.0, charge_sustaining=cs,
                   recuperation_round_trip=rt, recuperation_limit_w=20000.0)
        counts.update(eta=0, on=0)
        pf = ch.evaluate(p, v)["power_w"]
        assert counts == {"eta": 1, "on": 1}, (cs, counts)
        e = np.interp(v, [0.0, 10.0, 30.0], [0.8, 0.9, 0.92])
        running = p > 8000.0
        want = (np.where(running, 4000.0, 0.0) + np.where(running | cs, (np.maximum(p, 0) / e + 500.0) / 0.35, 0.0)
                + rt * np.maximum(np.minimum(p, 0.0), -20000.0) / e / 0.35)
        np.testing.assert_allclose(pf, want, rtol=1e-12)
        assert FUELS[ch.fuel]["lhv_j_per_kg"] > 0


def test_evaluation_on_a_steps_arrays_builds_no_broadcast_views(monkeypatch):
    """A step's speeds, durations and air temperature already have the samples' shape (or are
    one number): evaluate builds no broadcast view of them (three a fuel chain's step took),
    and the result is bit for bit that of inputs broadcast by hand."""
    ch = _fuel(running_fuel_per_k=0.01, aux_power_w=400.0)
    rng, n = np.random.default_rng(4), 5
    p, v, sig = rng.normal(0, 2e4, n), rng.uniform(0, 20, n), {"ambient_c": np.full(n, 3.0)}
    views, real = [], np.broadcast_to

    def spy(x, shape, *a, **kw):
        views.append(shape)
        return real(x, shape, *a, **kw)

    monkeypatch.setattr(np, "broadcast_to", spy)
    out = ch.evaluate(p, v, 0.5, sig)
    assert views == []
    by_hand = ch.evaluate(p, np.array(v), np.full(n, 0.5), {"ambient_c": np.array([3.0])})
    assert set(out) == set(by_hand)
    for k in out:
        np.testing.assert_array_equal(out[k], by_hand[k])
    np.testing.assert_array_equal(ch.evaluate(p, 7.0, 0.5, sig)["fuel_l"],
                                  ch.evaluate(p, np.full(n, 7.0), np.full(n, 0.5), sig)["fuel_l"])


def test_a_step_evaluates_the_chains_of_its_vehicles_into_their_columns():
    """Each chain of a step's vehicles (a fuel car, a battery car, a bounded hybrid, a plug-in
    hybrid, in any mix) books into its own columns what it books alone on those vehicles, and
    chains none of the step's vehicles uses book zeros."""
    hyb = dict(engine_off_below_w=8000.0, charge_sustaining=True, recuperation_round_trip=0.64,
               recuperation_limit_w=30000.0, aux_power_w=500.0)
    from sumo_drvpw.model.chain_plugin import depleting_from_dict
    plug = depleting_from_dict({"predicts": "fuel", "charge_sustaining": True,
                                "depleting": {"usable_j": 3e5, "traction_efficiency": 0.8,
                                              "recuperation_efficiency": 0.6}}, "t.toml")
    chains = [_fuel(), EnergyChain(predicts="battery", aux_power_w=300.0, traction_efficiency=0.9),
              _fuel(battery_usable_j=1e5, **hyb), _fuel(depleting=plug, **hyb)]
    names = ["f", "b", "h", "p"]
    led = ChainLedger(names, chains, 5)
    alone = [ChainLedger([nm], [c], 5) for nm, c in zip(names, chains)]
    rng, n = np.random.default_rng(8), 6
    for step in range(25):
        app = (rng.uniform(size=(n, 4)) < 0.3).astype(float)
        p, v, e = rng.normal(0, 2e4, (n, 4)), rng.uniform(0, 20, n), rng.integers(0, 5, n)
        q = led.book(np.arange(n), e, v, 1.0, p, app=app)
        cols = [alone[k].book(np.arange(n), e, v, 1.0, p[:, [k]], app=app[:, [k]]) for k in range(4)]
        np.testing.assert_array_equal(q, np.concatenate(cols, axis=1), err_msg=str(step))


def test_a_chain_of_some_of_the_steps_vehicles_spreads_back_only_what_the_step_reads():
    """A chain that applies to some of a step's vehicles (a mixed fleet) is evaluated on those
    and its outputs spread back to every vehicle: only the outputs the caller reads (a fuel
    chain's thirteen, of which a step books five), each equal to the whole spread's."""
    from sumo_drvpw.model.mmpevem import evaluate_where

    ch = _fuel(running_fuel_per_k=0.01, engine_max_w=30000.0)
    rng, n = np.random.default_rng(6), 7
    p, v, sel = rng.normal(0, 3e4, n), rng.uniform(0, 20, n), np.array([1, 0, 1, 1, 0, 0, 1], bool)
    sig = {"ambient_c": np.full(n, 2.0)}
    full = evaluate_where(ch, sel, p, v, 1.0, sig)
    read = {"power_j", "fuel_l", "co2_kg", "over_engine_j", "invalid"}
    part = evaluate_where(ch, sel, p, v, 1.0, sig, read)
    assert set(part) == read & set(full) and len(full) > len(part)
    for k in part:
        np.testing.assert_array_equal(part[k], full[k])
        assert not part[k][~sel].any()


def test_an_efficiency_table_builds_its_interpolator_once(monkeypatch):
    """A table evaluated every step builds its scipy interpolator once (it was built per call),
    again only when its values or an axis are replaced, and not pickled with it; its values are
    bit for bit a fresh interpolator's, clipped to the axes, |p| on the power axis."""
    import pickle

    import scipy.interpolate

    real, built = scipy.interpolate.RegularGridInterpolator, []

    class Counting(real):
        def __init__(self, *a, **kw):
            built.append(1)
            super().__init__(*a, **kw)

    monkeypatch.setattr(scipy.interpolate, "RegularGridInterpolator", Counting)
    rng = np.random.default_rng(7)
    t = Table(rng.uniform(0.7, 0.95, (4, 5)), np.array([0.0, 5.0, 15.0, 40.0]),
              np.array([0.0, 5e3, 2e4, 5e4, 9e4]))
    for k in range(6):
        v, p = rng.uniform(-1.0, 45.0, 7), rng.normal(0.0, 4e4, 7)
        want = real((t.speed_mps, t.power_w), t.values, method="linear")(
            np.column_stack([np.clip(v, 0.0, 40.0), np.clip(np.abs(p), 0.0, 9e4)]))
        np.testing.assert_array_equal(t(v, p), want)
    assert len(built) == 1
    t.values = t.values * 0.9  # replaced: built anew, at the new values
    np.testing.assert_array_equal(t(10.0, 1e4), real((t.speed_mps, t.power_w), t.values)([[10.0, 1e4]]))
    assert len(built) == 2
    back = pickle.loads(pickle.dumps(t))
    assert "_interp" not in back.__dict__
    np.testing.assert_array_equal(back(v, p), t(v, p))
    one = Table(np.array([0.8, 0.9, 0.92]), speed_mps=np.array([0.0, 10.0, 30.0]))  # one axis
    np.testing.assert_array_equal(one(v, p), real((one.speed_mps,), one.values)(np.clip(v, 0.0, 30.0)[:, None]))
    np.testing.assert_allclose(one(v, p), np.interp(np.clip(v, 0.0, 30.0), [0.0, 10.0, 30.0], [0.8, 0.9, 0.92]),
                               rtol=1e-15)


def test_mmpevem_battery_builds_no_broadcast_views_of_a_steps_arrays(monkeypatch):
    """SUMO's MMPEVEM motor and battery (model/mmpevem.SumoMotor.battery) on a step's arrays
    with signals missing (one number each) and a scalar or per-vehicle auxiliary power builds
    no broadcast view (it built five, and its loss map two more, per call and step); every
    output is bit for bit that of the inputs broadcast by hand."""
    from sumo_drvpw.model.mmpevem import mmpevem_equation

    mo = mmpevem_equation("x", {"maximumRecuperationPower": "40000"}, 1500.0, "x")[0].chain.motor
    rng, n = np.random.default_rng(11), 6
    p, v = rng.normal(0.0, 3e4, n), rng.uniform(0.0, 40.0, n)
    v[2] = 0.0  # standing: the holding force
    sig = {"accel_mps2": rng.normal(0.0, 1.0, n)}
    full = {"accel_mps2": sig["accel_mps2"], "grade_rad": np.zeros(n), "load_kg": np.zeros(n)}
    views = []
    real_to, real_arrays = np.broadcast_to, np.broadcast_arrays

    def spy_to(x, shape, *a, **kw):
        views.append(shape)
        return real_to(x, shape, *a, **kw)

    def spy_arrays(*a, **kw):
        views.append("arrays")
        return real_arrays(*a, **kw)

    for aux in (None, 250.0, rng.uniform(100.0, 900.0, n)):
        monkeypatch.setattr(np, "broadcast_to", spy_to)
        monkeypatch.setattr(np, "broadcast_arrays", spy_arrays)
        out = mo.battery(p, v, sig, aux_w=aux)
        monkeypatch.undo()
        assert views == [], (aux, views)
        by_hand = mo.battery(p, v.copy(), full, aux_w=np.full(n, mo.aux_power_w if aux is None else 0.0)
                             + (0.0 if aux is None else aux))
        assert set(out) == set(by_hand)
        for k in out:
            assert np.asarray(out[k]).shape == (n,), k
            np.testing.assert_array_equal(out[k], by_hand[k], err_msg=k)
    np.testing.assert_array_equal(mo.battery(p, 7.0, sig)["power_w"], mo.battery(p, np.full(n, 7.0), sig)["power_w"])


def test_a_chain_of_some_vehicles_takes_their_rows_without_numpy_s_shape_wrappers(monkeypatch):
    """evaluate_where (a chain booking some of a step's vehicles) selects each per-vehicle
    input's rows with one search of the mask, without np.ndim and np.shape on the step's
    arrays (four calls per input and chain each step before); numbers and lists are taken as
    before, and the outputs are bit for bit the chain's on the selected rows, zeros elsewhere."""
    from sumo_drvpw.model.mmpevem import evaluate_where

    ch = _fuel(traction_efficiency=0.3, aux_power_w=400.0, running_fuel_per_k=0.01)
    rng, n = np.random.default_rng(12), 9
    sel = np.array([True, False, True, True, False, False, True, False, True])
    p, v = rng.normal(0.0, 2e4, n), rng.uniform(0.0, 30.0, n)
    sig = {"ambient_c": rng.uniform(-5.0, 25.0, n), "accel_mps2": rng.normal(0.0, 1.0, n)}
    calls, real_ndim, real_shape = [], np.ndim, np.shape
    monkeypatch.setattr(np, "ndim", lambda x: calls.append("ndim") or real_ndim(x))
    monkeypatch.setattr(np, "shape", lambda x: calls.append("shape") or real_shape(x))
    out = evaluate_where(ch, sel, p, v, 0.5, sig, None)
    assert calls == []
    monkeypatch.undo()
    want = ch.evaluate(p[sel], v[sel], 0.5, {k: x[sel] for k, x in sig.items()})
    assert set(out) == set(want)
    for k in out:
        np.testing.assert_array_equal(out[k][sel], want[k], err_msg=k)
        assert not out[k][~sel].any(), k
    listed = evaluate_where(ch, sel, p.tolist(), v, [0.5] * n, {k: x.tolist() for k, x in sig.items()}, None)
    for k in out:
        np.testing.assert_array_equal(listed[k], out[k], err_msg=k)


def test_a_steps_applicability_is_read_once_while_it_repeats():
    """A few vehicles' ``app`` (which chains book which vehicle) rarely changes from step to
    step: the mask, the chains to evaluate and ``app`` per column are made once per distinct
    ``app`` and step length and kept (a step of many vehicles keeps none); every total is
    bit for bit that of a ledger that makes them anew each step."""
    chains = [_fuel(), EnergyChain(predicts="battery", aux_power_w=300.0, traction_efficiency=0.9), _fuel()]
    kept, fresh = (ChainLedger(["f", "b", "g"], chains, 40) for _ in range(2))
    rng, n = np.random.default_rng(11), 5
    first, second = np.array([[1, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0], [0, 1, 0]], float), np.ones((n, 3))
    for step in range(40):
        app = (first if step < 15 or step >= 30 else second).copy()  # (a new array each step, as the loop's)
        p, v, e = rng.normal(0, 2e4, (n, 3)), rng.uniform(0, 20, n), rng.permutation(40)[:n]
        fresh._apps.clear()
        for led in (kept, fresh):
            led.book(np.arange(n), e, v, 1.0, p, app=app)
    assert len(kept._apps) == 2
    for name in ("_veh", "veh_dist", "veh_time", "_app", "_edge", "edge_dist", "booked_any"):
        np.testing.assert_array_equal(getattr(kept, name), getattr(fresh, name), err_msg=name)
    big = ChainLedger(["f", "b", "g"], chains, 400)
    big.book(np.arange(100), np.arange(100), rng.uniform(0, 20, 100), 1.0, rng.normal(0, 2e4, (100, 3)),
             app=np.ones((100, 3)))
    assert big._apps == {}
