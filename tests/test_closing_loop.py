"""Closing the loop on real data (issue #11): the temperature factor ``cold`` of the term
grammar, evaluated the same by the equation evaluator and the SUMO ledger's fast path."""

import numpy as np
import pytest

from sumo_drvpw.model.constants import G, T_REF_C
from sumo_drvpw.model.equations import Equation
from sumo_drvpw.model.terms import Inputs, category_of, term_matrix
from sumo_drvpw.sim.ledger import LEDGER_CATEGORIES, EquationSet


def _inputs(n, amb=None, seed=0):
    rng = np.random.default_rng(seed)
    sig = {} if amb is None else {"ambient_c": np.asarray(amb, float)}
    return Inputs(rng.uniform(0, 35, n), rng.uniform(-2, 2, n), rng.uniform(-0.05, 0.05, n),
                  np.zeros(n), rng.uniform(1200, 1800, n), np.full(n, 1.2), sig)


def test_cold_is_reference_minus_ambient_and_zero_without_temperature():
    x = _inputs(3, [0.0, 20.0, np.nan])
    # hand: T_ref 20 °C − 0 °C = 20 K; at 20 °C 0 K; unknown temperature → reference (0 K)
    np.testing.assert_array_equal(term_matrix(["cold"], x)[:, 0], [20.0, 0.0, 0.0])
    assert T_REF_C == 20.0
    np.testing.assert_array_equal(term_matrix(["cold"], _inputs(4))[:, 0], np.zeros(4))
    assert category_of("roll*cold") == "roll" and category_of("cold*v^2") == "roll"


def test_roll_cold_is_the_iso_temperature_correction_of_c_r():
    # c_r(T) = c_r0·(1 + k·(T_ref − T)); c_r0 0.01, k 0.008/K (ISO 28580), at −5 °C: 1.2·c_r0
    n = 50
    x = _inputs(n, np.full(n, -5.0))
    eq = Equation("crT", {"roll": 0.01, "roll*cold": 0.01 * 0.008})
    want = 0.01 * 1.2 * x.mass * G * x.v * np.cos(x.theta)
    np.testing.assert_allclose(eq.power(x), want, rtol=1e-12)


@pytest.mark.parametrize("amb", [None, "field"])
def test_ledger_fast_path_books_the_cold_terms_as_the_evaluator(amb):
    n = 400
    rng = np.random.default_rng(3)
    x = _inputs(n, None if amb is None else rng.uniform(-10, 35, n), seed=4)
    eqs = [Equation("a", {"acc": 1.2, "grade": 1.05, "aero_rho": 0.58, "roll": 0.02,
                          "roll*cold": 3e-4}),
           Equation("b", {"acc": 1.0, "roll": 0.012, "cold*v^2": 0.17}, mass_kg=1500.0)]
    pc = EquationSet(eqs).category_powers(x)
    for e, eq in enumerate(eqs):
        cp = eq.category_powers(x)
        for k, cat in enumerate(LEDGER_CATEGORIES):
            np.testing.assert_allclose(pc[:, e, k], cp.get(cat, np.zeros(n)), rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(pc[:, e].sum(1), eq.power(x), rtol=1e-12, atol=1e-9)
    if amb is None:   # no temperature: the equation at the reference temperature
        ref = Equation("a0", {k: c for k, c in eqs[0].terms.items() if "cold" not in k})
        np.testing.assert_allclose(eqs[0].power(x), ref.power(x), rtol=1e-12)


# ------------------------------------------- physical candidates chosen on whole trips

def test_ledger_books_the_inertia_by_direction_in_the_acc_category():
    """acc_pos = m·v_acc·max(a, 0): the SUMO ledger books it under 'acc' as the evaluator
    does, with the step's kinetic-energy speed v_acc when the loop gives one; over a step
    that speeds up it adds c·ΔKE/Δt, over one that slows down nothing."""
    n = 300
    x = _inputs(n, seed=5)
    x.v_acc = x.v + 0.1
    eq = Equation("dir", {"acc": 1.04, "acc_pos": 0.26, "roll": 0.014})
    pc = EquationSet([eq]).category_powers(x)
    k = LEDGER_CATEGORIES.index("acc")
    want = x.mass * x.v_acc * (1.04 * x.a + 0.26 * np.maximum(x.a, 0.0))
    np.testing.assert_allclose(pc[:, 0, k], want, rtol=1e-12)
    np.testing.assert_allclose(pc[:, 0].sum(1), eq.power(x), rtol=1e-12, atol=1e-9)
    assert category_of("acc_pos") == "acc"


def _trips(k_cr=0.0, recup_scale=1.0, n_trips=12, n=1500, seed=7, acc_up=None):
    """Synthetic trips at different ambient temperatures; truth at the motor shaft:
    1.1·m·v·a + m·g·v·sin θ + 0.35·v³ + c_r(T)·m·g·v·cos θ, c_r(T) = 0.012·(1 + k·(20 − T)),
    recuperation × ``recup_scale``; noise 400 W. With ``acc_up`` the inertial factor is
    ``acc_up`` while speeding up (1.1 while slowing down), and the trips differ in how much
    they speed up and slow down (stop-and-go to steady)."""
    rng = np.random.default_rng(seed)
    parts = []
    for i in range(n_trips):
        amp, per = (8.0, 90.0) if acc_up is None else (2.0 + 9.0 * (i % 4) / 3.0, 40.0 + 25.0 * (i % 3))
        v = np.clip(14 + amp * np.sin(np.arange(n) / per + i) + np.cumsum(rng.normal(0, 0.1, n)), 0.5, 33)
        a = np.gradient(v, 0.5)
        th = 0.03 * np.sin(np.arange(n) / (80.0 + 10 * i) + i)
        t_amb = -5.0 + 35.0 * i / (n_trips - 1)
        parts.append((v, a, th, np.full(n, t_amb), np.full(n, f"T{i:02d}")))
    v, a, th, amb, trip = (np.concatenate(z) for z in zip(*parts))
    m = np.full(v.size, 1500.0)
    x = Inputs(v, a, th, np.zeros(v.size), m, np.full(v.size, 1.2), {"ambient_c": amb}, trip)
    cr = 0.012 * (1.0 + k_cr * (T_REF_C - amb))
    c_acc = 1.1 if acc_up is None else np.where(a > 0, acc_up, 1.1)
    p = c_acc * m * v * a + m * G * v * np.sin(th) + 0.35 * v ** 3 + cr * m * G * v * np.cos(th)
    p = np.where(p < 0, recup_scale * p, p) + rng.normal(0, 400.0, v.size)
    return x, p, np.ones(v.size, bool), np.full(v.size, 0.5), trip


BASE = ["acc", "aero", "roll", "grade"]


def test_planted_cr_temperature_is_found_with_its_k():
    from sumo_drvpw.fit.physical import select_physical

    sel = select_physical(*_trips(k_cr=0.01), BASE, candidates=("rho(T)", "c_r(T)", "cold drag"))
    assert sel["chosen"] == ["c_r(T)"]
    step = next(s for s in sel["steps"] if s["accepted"])
    assert step["reading"]["value"] == pytest.approx(0.01, rel=0.15)   # planted k 1 %/K
    assert sel["cv"]["mean_abs_error"] < sel["base_cv"]["mean_abs_error"]


def test_nothing_planted_nothing_found():
    from sumo_drvpw.fit.physical import select_physical

    sel = select_physical(*_trips(), BASE)
    assert sel["chosen"] == [], sel["steps"]


def test_planted_recuperation_regime_is_found_and_scale_recovered():
    from sumo_drvpw.fit.physical import regime_fit, select_physical

    x, p, use, dt, trip = _trips(recup_scale=0.7)
    sel = select_physical(x, p, use, dt, trip, BASE, candidates=("regime", "c_r(T)"))
    assert sel["chosen"] == ["regime"]
    b, r = regime_fit(term_matrix(BASE, x), p, True)
    assert 1 + r == pytest.approx(0.7, abs=0.03)
    assert dict(zip(BASE, b))["acc"] == pytest.approx(1.1, rel=0.03)


def test_planted_inertia_by_direction_is_found_with_its_efficiency():
    """The drivetrain delivers kinetic energy at 1/η and returns it at η: inertial factor
    1.1/0.9² = 1.358 while speeding up, 1.1 while slowing down. The candidate is kept and
    reads η = sqrt(1.1/1.358) = 0.9; the acc_pos term evaluates m·v·max(a, 0)."""
    from sumo_drvpw.fit.physical import select_physical

    x, p, use, dt, trip = _trips(acc_up=1.1 / 0.81)
    sel = select_physical(x, p, use, dt, trip, BASE, candidates=("inertia by direction", "c_r(T)", "regime"))
    assert sel["chosen"][0] == "inertia by direction", sel["steps"]
    step = next(s for s in sel["steps"] if s["accepted"])
    assert step["reading"]["value"] == pytest.approx(0.9, abs=0.02)
    assert "acc_pos" in sel["terms"]
    np.testing.assert_array_equal(term_matrix(["acc_pos"], x)[:, 0], x.mass * x.v * np.maximum(x.a, 0.0))


def test_inertia_by_direction_is_not_found_when_the_drivetrain_is_symmetric():
    from sumo_drvpw.fit.physical import select_physical

    sel = select_physical(*_trips(acc_up=1.1), BASE, candidates=("inertia by direction",))
    assert sel["chosen"] == [], sel["steps"]


def test_trip_cv_energy_is_the_compare_definition():
    # one fold's held-out trip energy equals trip_energy of the same prediction (no other mask)
    from sumo_drvpw.fit.compare import trip_energy
    from sumo_drvpw.fit.physical import regime_fit, regime_power, trip_cv

    x, p, use, dt, trip = _trips(n_trips=4, n=800)
    cv = trip_cv(x, p, use, dt, trip, BASE, k=4)
    X = term_matrix(BASE, x)
    test = trip == "T00"
    b, r = regime_fit(X[~test], p[~test], False)
    want = trip_energy(regime_power(X[test], b, r), p[test], dt[test], trip[test])["trips"]["T00"]
    assert cv["errors"]["T00"] == pytest.approx(want["error"], rel=1e-9)
    # measured side by hand: Σ max(P, 0)·Δt
    assert want["measured_j"] == pytest.approx(float(np.sum(np.maximum(p[test], 0)) * 0.5))


def test_trip_cv_net_energy_is_the_compare_definition():
    """energy="net": a held-out trip's error (no descent here) is trip_net_energy's (Σ P·Δt),
    not the traction energy's; and the selection judged on it finds a planted recuperation
    scale and nothing where none is planted."""
    from sumo_drvpw.fit.compare import trip_net_energy
    from sumo_drvpw.fit.physical import regime_fit, regime_power, select_physical, trip_cv

    x, p, use, dt, trip = _trips(n_trips=4, n=800, recup_scale=0.7)
    cv = trip_cv(x, p, use, dt, trip, BASE, k=4, energy="net")
    X = term_matrix(BASE, x)
    test = trip == "T01"
    b, r = regime_fit(X[~test], p[~test], False)
    want = trip_net_energy(regime_power(X[test], b, r), p[test], dt[test], trip[test])["trips"]["T01"]
    assert cv["errors"]["T01"] == pytest.approx(want["error"], rel=1e-9)
    assert want["measured_j"] == pytest.approx(float(np.sum(p[test]) * 0.5))   # Σ P·Δt by hand
    assert cv["errors"]["T01"] != pytest.approx(trip_cv(x, p, use, dt, trip, BASE, k=4)["errors"]["T01"], rel=1e-3)
    assert select_physical(*_trips(recup_scale=0.7), BASE, candidates=("regime",), energy="net")["chosen"] == ["regime"]
    assert select_physical(*_trips(), BASE, candidates=("regime",), energy="net")["chosen"] == []


def test_net_energy_error_stays_bounded_on_a_descent():
    """fit.trip_energy.net_energy_errors, by hand: a trip whose measured net energy is at least
    NET_SHARE_MIN of its traction energy gets trip_net_energy's relative error; a descent
    (net 0.5 % of traction) gets its net miss as a share of its traction energy, not the
    relative error's ×20 blow-up; a trip without traction gets NaN."""
    from sumo_drvpw.fit.trip_energy import NET_SHARE_MIN, net_energy_errors, trip_net_energy

    # trip A: 10 s at +20 kW, 10 s at −5 kW (net 150 kJ of 200 kJ traction);
    # trip D: 10 s at +20 kW, 10 s at −19.9 kW (net 1 kJ of 200 kJ); trip S: standing, braking
    meas = np.array([20e3] * 10 + [-5e3] * 10 + [20e3] * 10 + [-19.9e3] * 10 + [-1e3] * 5)
    pred = meas * 1.0
    pred[:10] *= 1.1             # A: traction over-predicted by 10 % → net +20 kJ
    pred[20:30] *= 1.1           # D: the same miss, +20 kJ on a net of 1 kJ
    trip = np.array(["A"] * 20 + ["D"] * 20 + ["S"] * 5)
    e = net_energy_errors(pred, meas, 1.0, trip)
    assert 150e3 >= NET_SHARE_MIN * 200e3 > 1e3
    assert e["A"] == pytest.approx(trip_net_energy(pred, meas, 1.0, trip)["trips"]["A"]["error"], rel=1e-12)
    assert e["A"] == pytest.approx(20e3 / 150e3)
    assert e["D"] == pytest.approx(20e3 / 200e3)                     # not 20 kJ / 1 kJ = 20
    assert np.isnan(e["S"])


def test_trip_cv_k1_is_the_in_sample_fit():
    """k = 1: one fit on every trip, each trip's error in sample (the same definition), and
    never worse than the held-out errors on average."""
    from sumo_drvpw.fit.compare import trip_energy
    from sumo_drvpw.fit.physical import regime_fit, regime_power, trip_cv

    x, p, use, dt, trip = _trips(n_trips=6, n=600)
    rng = np.random.default_rng(3)
    p = p * np.repeat(1 + 0.05 * rng.standard_normal(6), 600)  # a per-trip scatter no input carries
    fit_all = trip_cv(x, p, use, dt, trip, BASE, k=1)
    X = term_matrix(BASE, x)
    b, r = regime_fit(X, p, False)
    want = trip_energy(regime_power(X, b, r), p, dt, trip)["trips"]
    assert fit_all["folds"] == 1 and set(fit_all["errors"]) == set(want)
    for t, v in want.items():
        assert fit_all["errors"][t] == pytest.approx(v["error"], rel=1e-9)
    assert fit_all["mean_abs_error"] <= trip_cv(x, p, use, dt, trip, BASE, k=3)["mean_abs_error"]


def test_closed_loop_form_runs_in_sumo_at_the_reference_temperature(tmp_path):
    """An equation with the temperature terms the closed loop carries runs in a real SUMO
    run (log-only [ambient_c] terms are refused there); without an air temperature passed to
    the loop, 'cold' is 0 and it books what the same equation without them books."""
    from pathlib import Path

    from sumo_drvpw.sim import run_scenario

    city = Path(__file__).resolve().parent.parent / "scenarios" / "city.toml"
    base = {"acc": 1.27, "grade": 1.05, "aero": 0.33, "roll": 0.015}
    closed = Equation("closed", dict(base, **{"cold*v^2": 0.17, "roll*cold": 2e-4}))
    ref = Equation("ref", base)
    s = run_scenario(city, tmp_path / "o", end=120, equations=[closed, ref], figures=False)
    assert s["samples"] > 0
    e_c, e_r = s["equations"]["closed"]["energy_j"]["city"], s["equations"]["ref"]["energy_j"]["city"]
    assert sum(abs(v) for v in e_r.values()) > 0
    for cat, val in e_r.items():
        assert e_c[cat] == pytest.approx(val, rel=1e-12, abs=1e-9)


def test_split_rule_second_split_is_fixed_up_front_and_differs():
    from sumo_drvpw.validation import closing_the_loop as mod

    trips = [f"Trip{s}{i:02d}" for s in "AB" for i in range(1, 26)]
    a, b = mod.split_trips(trips, second=True)
    t = sorted(trips)
    assert a == t[4::5] and b == t[2::5] and len(a) == len(b) == 10
    assert not set(a) & set(b)
    assert mod.split_trips(trips) == [a]                          # one split unless asked
    assert mod.split_trips(["x", "y"], second=True) == [["x"], ["y"]]
    assert mod.split_trips([f"t{i}" for i in range(6)], second=True) == [["t2", "t5"]]


def test_sumo_books_the_cold_terms_at_the_scenario_air_temperature(tmp_path):
    """With air.temperature_c = 0 °C in the scenario, the loop passes ambient_c = 0 to the
    equations: 'roll + k·roll*cold' books exactly what 'roll·(1 + 20 K·k)' books (c_r(T) at
    20 K below the reference), and the chain ledger is given the same temperature."""
    from pathlib import Path

    from sumo_drvpw.sim import run_scenario

    import sumo_drvpw.sim as sim

    src = Path(sim.__file__).parent / "builtin" / "scenarios" / "city.toml"
    text = src.read_text(encoding="utf-8").replace("temperature_c = 20.0", "temperature_c = 0.0").replace(
        'config = "city.sumocfg"', f'config = "{(src.parent / "city.sumocfg").as_posix()}"')
    assert "temperature_c = 0.0" in text and str(src.parent) in text
    sc = tmp_path / "city.toml"
    sc.write_text(text, encoding="utf-8")
    base = {"acc": 1.27, "grade": 1.05, "aero": 0.33}
    k = 0.01
    cold = Equation("cold", dict(base, roll=0.015, **{"roll*cold": 0.015 * k}))
    warm = Equation("warm", dict(base, roll=0.015 * (1 + (T_REF_C - 0.0) * k)))
    ref = Equation("ref", dict(base, roll=0.015))
    s = run_scenario(sc, tmp_path / "o", end=120, equations=[cold, warm, ref], figures=False)
    tot = {n: sum(s["equations"][n]["energy_j"]["city"].values()) for n in ("cold", "warm", "ref")}
    assert tot["cold"] == pytest.approx(tot["warm"], rel=1e-9)
    assert tot["cold"] > tot["ref"] * 1.001   # the cold term did book something


# ------------------------------------- input checks: why do held-out trips miss (inputs only)

def _dropout_log(seed=11):
    from sumo_drvpw.synth.effects import synth_trips

    df, _ = synth_trips(n_trips=3, minutes=4.0, seed=seed)
    # as the TUM i3 logs: speed in whole 0.01 km/h, accelerometer in 0.01 m/s²
    df["speed_mps"] = np.round(df["speed_mps"] * 360.0) / 360.0
    df["imu_accel_mps2"] = np.round(df["imu_accel_mps2"], 2)
    return df


def _mask(df, margin_m=0.0):
    from sumo_drvpw.fit.input_checks import dropout_mask

    codes = np.unique(df["trip_id"], return_inverse=True)[1]
    return dropout_mask(df["time_s"], [df["speed_mps"], df["imu_accel_mps2"]], codes,
                        df["speed_mps"], margin_m=margin_m)


def test_dropout_nothing_planted_nothing_found():
    df = _dropout_log()
    assert not _mask(df).any()
    assert not _mask(df, margin_m=100.0).any()


@pytest.mark.parametrize("mode", ["hold", "linear"])
def test_dropout_planted_hold_or_linear_fill_is_found_exactly(mode):
    from sumo_drvpw.fit.input_checks import dropout_report
    from sumo_drvpw.synth.effects import plant_dropout

    df = _dropout_log()
    planted = plant_dropout(df, "synth-2", 70.0, 30.0, mode)
    assert planted.sum() > 200                       # 30 s at 8 Hz
    found = _mask(df)
    assert np.all(found[planted])
    # only the window's real edge rows (start; in linear mode also the end) besides
    edge = np.flatnonzero(found & ~planted)
    i0, i1 = np.flatnonzero(planted)[[0, -1]]
    assert set(edge) <= {i0 - 1, i1 + 1}
    rep = dropout_report(found, df["trip_id"].to_numpy(), np.full(len(df), 0.125))
    assert list(rep) == ["synth-2"] and 30.0 <= rep["synth-2"] <= 30.3
    # the grade-smoothing margin: the extra samples lie within 100 m of travel, on the same trip
    wide = _mask(df, margin_m=100.0)
    extra = np.flatnonzero(wide & ~found)
    assert len(extra) > 0 and set(df["trip_id"].to_numpy()[wide]) == {"synth-2"}
    v = df["speed_mps"].to_numpy()
    dist = np.cumsum(np.r_[0.0, 0.5 * (v[1:] + v[:-1]) * 0.125])
    f = np.flatnonzero(found)
    gap = np.minimum(np.abs(dist[extra] - dist[f[0]]), np.abs(dist[extra] - dist[f[-1]]))
    assert gap.max() <= 100.0 + 1e-9
    # just beyond the margin on either side: not marked
    t = df["trip_id"].to_numpy() == "synth-2"
    out = t & ((dist < dist[f[0]] - 100.5) | (dist > dist[f[-1]] + 100.5))
    assert out.any() and not wide[out].any()


def test_a_standstill_whose_accelerometer_reads_one_value_is_no_dropout():
    """A car parked for minutes: its speed is 0 and a coarse or filtered accelerometer may read
    one constant value — held, but no logger dropout (a helper's rehearsal: 25 min parked in an
    i3 trip were left out as a dropout, 15,960 of 23,808 samples, with their battery draw);
    the same stretch held while moving still is one, and so is a 0 held while the car drove
    off (the speed jumps to what it reached when the logger comes back)."""
    df = _dropout_log()
    own = np.flatnonzero(df["trip_id"].to_numpy() == "synth-2")
    i = own[-8 * 60:]                                  # its last 60 s at 8 Hz: parked
    parked = df.copy()
    parked.loc[i, "speed_mps"] = 0.0
    parked.loc[i, "imu_accel_mps2"] = 0.0123
    assert not _mask(parked).any()
    moving = df.copy()
    moving.loc[i, "speed_mps"] = 7.0
    moving.loc[i, "imu_accel_mps2"] = 0.0123
    assert _mask(moving)[i].all()
    k = own[400:400 + 8 * 60]                          # 60 s mid-trip, driving on after it
    drove_off = df.copy()
    drove_off.loc[k, "speed_mps"] = 0.0
    drove_off.loc[k, "imu_accel_mps2"] = 0.0123
    assert df["speed_mps"].to_numpy()[k[-1] + 1] > 2.0 and _mask(drove_off)[k].all()
    # a wheel-speed sensor's first reading after 0 (it reads 0 below a few km/h): 0.6 m/s
    # 0.05 s after a 20-Hz stop is a car pulling away, no dropout
    from sumo_drvpw.data.dropouts import dropout_mask

    t = np.arange(400) * 0.05
    v = np.r_[np.zeros(200), 0.6 + 0.1 * np.arange(200)]
    acc = np.r_[np.zeros(200), np.full(200, 2.0) + 0.01 * np.sin(np.arange(200))]
    assert not dropout_mask(t, [v, acc], np.zeros(400, int), v).any()


def test_accelerometer_offsets_hand_calculation():
    from sumo_drvpw.fit.input_checks import accelerometer_offsets

    # 10 s standing on a 2 % slope, then 100 s at 10 m/s up the same slope (1000 m, Δh 20 m)
    dt = 0.1
    v = np.r_[np.zeros(100), np.full(1000, 10.0)]
    s = 0.02
    h = 500.0 + s * np.cumsum(v * dt)
    o = 0.12                                          # mounting pitch offset [m/s²]
    imu = np.zeros_like(v) + G * s + o                # a = 0 throughout
    r = accelerometer_offsets(imu, np.zeros_like(v), v, h, np.full(v.size, dt), np.full(v.size, "T"))["T"]
    # elevation: Σ s_acc·ds = (G s + o)/G · 1000 m; Δh = 20 m − (first moving sample's step)
    dh = h[-1] - h[0]
    assert r["dh_m"] == pytest.approx(dh)
    assert r["offset_elevation"] == pytest.approx(G * ((G * s + o) / G * 1000.0 - dh) / 1000.0, rel=1e-12)
    assert r["offset_elevation"] == pytest.approx(o, abs=1e-12)
    assert r["offset_standstill"] == pytest.approx(G * s + o)   # the stop's slope is in it
    assert r["standstill_s"] == pytest.approx(10.0)
    assert r["max_gap_m"] < 0.25                      # the two agree (up to one step of 0.2 m)
    # a GPS elevation that starts 30 m high and settles within the first 100 m of travel
    h2 = h + np.where(np.cumsum(v * dt) < 100.0, 30.0, 0.0)
    r2 = accelerometer_offsets(imu, np.zeros_like(v), v, h2, np.full(v.size, dt), np.full(v.size, "T"))["T"]
    assert r2["max_gap_m"] > 25.0


def test_inertial_mass_finds_a_planted_undeclared_load():
    from sumo_drvpw.fit.input_checks import inertial_mass

    rng = np.random.default_rng(5)
    n = 6000
    trip = np.repeat(["A", "B"], n // 2)
    true_m = np.where(trip == "A", 1300.0, 1460.0)     # B carries 160 kg it did not declare
    x = Inputs(rng.uniform(3, 19, n), rng.uniform(-1.5, 1.5, n), rng.uniform(-0.04, 0.04, n),
               np.zeros(n), np.full(n, 1300.0), np.full(n, 1.2), {})
    p = (1.15 * true_m * x.a * x.v + 200.0 * x.v + 0.35 * x.v ** 3 + true_m * G * np.sin(x.theta) * x.v
         + rng.normal(0, 300.0, n))
    r = inertial_mass(p, x, np.ones(n, bool), trip)
    assert r["A"]["ratio"] == pytest.approx(1.15, rel=0.01)
    assert r["B"]["ratio"] / r["A"]["ratio"] == pytest.approx(1460.0 / 1300.0, rel=0.01)
    assert r["B"]["declared_kg"] == 1300.0


@pytest.mark.parametrize("offset", [0.0, 0.015])
def test_accelerometer_grade_offset_fixed_by_elevation(offset):
    from sumo_drvpw.fit.input_checks import offset_corrected_sin_grade

    # two trips over a hill; the accelerometer carries its mounting pitch (sin 0.015 ≈ 0.86°)
    # on trip 2 only; the elevation is the integral of the true grade
    rng = np.random.default_rng(2)
    n = 3000
    codes = np.repeat([0, 1], n)
    v = np.tile(rng.uniform(5, 20, n), 2)
    dt = np.full(2 * n, 0.1)
    s_true = np.tile(0.03 * np.sin(np.linspace(0, 3 * np.pi, n)), 2)
    h = np.concatenate([520.0 + np.cumsum(s_true[codes == k] * v[codes == k] * 0.1) for k in (0, 1)])
    s_acc = s_true + np.where(codes == 1, offset, 0.0)
    got = offset_corrected_sin_grade(s_acc, v, dt, codes, h)
    # Δh counts the steps after a trip's first sample, the sum includes it: exact here because
    # the true grade is 0 at each trip's start (sin 0); the offset is removed, the hill kept
    assert s_true[0] == 0.0 and s_true[n] == 0.0
    np.testing.assert_allclose(got, s_true, atol=1e-12)
    for k in (0, 1):
        i = codes == k
        assert np.sum(got[i] * v[i] * 0.1) == pytest.approx(h[i][-1] - h[i][0], abs=1e-9)


def test_log_dropouts_reads_a_drive_log_and_needs_an_accelerometer():
    """fit.input_checks.log_dropouts (used by the closing loop and the i3 chain validation):
    the planted hold of a read log is marked, widened by the log's grade-smoothing distance;
    without an accelerometer column nothing is marked (a steady cruise is no dropout)."""
    from sumo_drvpw.data.log import from_frame
    from sumo_drvpw.fit.input_checks import log_dropouts
    from sumo_drvpw.model.vehicles import load_vehicle
    from sumo_drvpw.synth.effects import plant_dropout

    df = _dropout_log()
    planted = plant_dropout(df, "synth-2", 70.0, 30.0, "hold")
    log = from_frame(df, load_vehicle("prius3"), name="planted")
    drop = log_dropouts(log)
    expect = _mask(df.reset_index(drop=True), margin_m=log.options.grade_window_m)
    assert np.array_equal(drop, expect) and np.all(drop[planted]) and drop.sum() > planted.sum()
    assert log_dropouts(from_frame(df.drop(columns=["imu_accel_mps2"]), load_vehicle("prius3"),
                                   name="no-imu")) is None


@pytest.mark.parametrize("run", ["i3", "i3_split2"])
def test_the_documented_closed_equation_reproduces_its_held_out_figures_through_compare(shared_data, tmp_path,
                                                                                       run, capsys):
    """docs/closing-the-loop/<run>/closed_equation.toml carries the corrections of its logs as
    [measurement]: `sumo-drvpw compare` on the held-out trips, with no flag, reads them the same
    way and reproduces the report's held-out row (R², per-trip traction-energy errors)."""
    import json
    import re
    from pathlib import Path

    from sumo_drvpw.cli import main as cli_main
    from sumo_drvpw.cli.import_ import write_log
    from sumo_drvpw.data.adapters import read
    from sumo_drvpw.fileio import read_toml

    docs = Path(__file__).resolve().parent.parent / "docs"
    eq_path = docs / "closing-the-loop" / run / "closed_equation.toml"
    doc = read_toml(eq_path, "equation")
    # the grade source the split chose on its training trips (a fusion, or the accelerometer
    # less the logger offset): a correction either way, which compare must apply unasked
    assert doc["measurement"]["grade"] in ("fused", "accelerometer") and doc["measurement"]["exclude_dropouts"] is True
    held = doc["provenance"]["held_out"]
    df, rep = read("bmw-i3-tum", shared_data / "bmw_i3_tum")
    sub = df[df["trip_id"].isin(held)].reset_index(drop=True)
    log = tmp_path / "held.parquet"
    write_log(sub, {"roles": {c: r for c, r in rep.get("roles", {}).items() if c in sub.columns}}, log)
    assert cli_main(["compare", str(log), "--vehicle", "bmw_i3", "--equation", str(eq_path),
                     "--out", str(tmp_path / "c")]) == 0
    assert "[measurement] of" in capsys.readouterr().out
    got = json.loads((tmp_path / "c" / "report.json").read_text(encoding="utf-8"))["equations"][doc["equation"]["name"]]
    md = (docs / "closing-the-loop.md").read_text(encoding="utf-8")
    section = md.split(f"### {run}: held out")[1]
    row = next(ln for ln in section.splitlines() if ln.startswith(f"| `{doc['equation']['name']}` |"))
    cells = [c.strip() for c in row.split("|")]
    assert got["r2"] == pytest.approx(float(cells[3]), abs=6e-4)
    per = dict(re.findall(r"(Trip\w+) ([+-]\d+\.\d) %", cells[6]))
    assert set(per) == set(held)
    for t, e in per.items():
        assert 100 * got["trip_energy"]["trips"][t]["error"] == pytest.approx(float(e), abs=0.051)


def test_study_writes_its_train_and_test_logs_with_the_adapters_roles(tmp_path):
    """validation.closing_the_loop_read.write_subset: the held-out trips (keep) or the rest,
    written as a log that reads back with the adapter's roles for the columns it has (the
    study's tracer leaves response columns out by them); a role of a column the log lacks is
    dropped. On the first move into the package it raised TypeError on any roles (bytes
    metadata keys passed as keywords)."""
    import pyarrow.parquet as pq

    import sumo_drvpw.synth.effects as E
    from sumo_drvpw.data.measured import load_measured
    from sumo_drvpw.data.roles import from_metadata, of_log
    from sumo_drvpw.validation.closing_the_loop_read import write_subset

    df, _ = E.synth_trips(3, 2.0, seed=3, effects=[E.LogPower()])
    df["pedal_pct"] = 1.0
    trips = sorted(df["trip_id"].unique())
    roles = {"pedal_pct": "response", "not_a_column": "load"}
    test = write_subset(df, trips[:1], tmp_path / "test.parquet", keep=True, roles=roles)
    train = write_subset(df, trips[:1], tmp_path / "train.parquet", keep=False, roles=roles)
    assert from_metadata(pq.read_schema(test).metadata) == {"pedal_pct": "response"}
    got_test, got_train = pq.read_table(test).to_pandas(), pq.read_table(train).to_pandas()
    assert sorted(got_test["trip_id"].unique()) == trips[:1]
    assert sorted(got_train["trip_id"].unique()) == trips[1:]
    assert len(got_test) + len(got_train) == len(df)
    assert of_log(load_measured([train], "prius3").log)["pedal_pct"]["role"] == "response"


def test_grade_options_of_the_script_declare_what_they_read(tmp_path):
    """Each grade option of the study's grid becomes the [measurement] a closed-loop
    equation declares: fused crossovers, per-trip offsets (∞), the logger's offset."""
    import math

    import sumo_drvpw.synth.effects as E

    from sumo_drvpw.validation import closing_the_loop_read as mod
    from sumo_drvpw.validation.closing_the_loop_fit import TAU_GRID_S

    df, _ = E.synth_trips(2, 2.0, seed=5, effects=[E.LogPower()])
    path = tmp_path / "log.parquet"
    df.drop(columns=["gps_elevation_m"]).to_parquet(path)
    # no elevation: no logger offset can be estimated, and the option is not offered
    assert math.isnan(mod.logger_offset(mod.load_checked(path, "prius3"))["offset_mps2"])
    df.drop(columns=["grade_rad"]).rename(columns={"gps_elevation_m": "elevation_m"}).to_parquet(path)
    assert mod.LOGGER_OFFSET in TAU_GRID_S and math.inf in TAU_GRID_S
    m = mod.measurement_of(path, 0.0, True, 120.0)
    assert (m.grade, m.fusion_tau_s, m.accelerometer_offset_mps2) == ("fused", 120.0, None)
    assert mod.measurement_of(path, 0.0, True, 60).grade == "fused"       # a crossover given as int
    m = mod.measurement_of(path, 0.0, True, "1000 m")                     # a crossover over distance
    assert (m.grade, m.fusion_tau_s, m.fusion_distance_m) == ("fused", None, 1000.0)
    assert any(mod.distance_crossover_m(t) for t in TAU_GRID_S)
    m = mod.measurement_of(path, 0.0, True, math.inf)
    assert (m.grade, m.accelerometer_offset_mps2) == ("accelerometer", None)
    m = mod.measurement_of(path, 0.0, True, mod.LOGGER_OFFSET, 0.03)
    assert (m.grade, m.accelerometer_offset_mps2) == ("accelerometer", 0.03)
    assert "fixed offset of +0.03 m/s²" in m.describe()
    # without the tracer's accelerometer finding the grade stays as logged
    assert mod.measurement_of(path, 0.0, False, mod.LOGGER_OFFSET, 0.03).grade == "logged"
    # the logger offset of the script is the median of the trips' own (inputs only)
    off = mod.logger_offset(mod.load_checked(path, "prius3"))
    assert off["trips"] == 2 and abs(off["offset_mps2"]) < 0.05


def test_moving_check_separates_a_planted_standing_and_moving_constant(tmp_path):
    """validation.closing_the_loop_checks.moving_check on synthetic trips whose power is a known road
    load + 400 W drawn all the time + 1000 W more while moving: the split recovers both,
    the power measured standing is the 400 W, and one constant alone lands in between."""
    import sumo_drvpw.synth.effects as E
    from sumo_drvpw.data.measured import load_measured
    from sumo_drvpw.model.equations import Equation
    from sumo_drvpw.validation.closing_the_loop_checks import moving_check

    df, _ = E.synth_trips(3, 6.0, seed=8, effects=[E.LogPower()])
    path = tmp_path / "log.parquet"
    df.to_parquet(path)
    road = Equation("d", {"acc": 1.0, "aero": 0.35, "roll": 0.01, "grade": 1.0})
    m = load_measured([path], "prius3")
    assert 0.02 < float(np.mean(m.inputs.v < 0.1)) < 0.6          # the trips do stand
    moving = (m.inputs.v >= 0.1).astype(float)
    df["power_w"] = road.power(m.inputs) + 400.0 + 1000.0 * moving
    df.to_parquet(path)
    r = moving_check(load_measured([path], "prius3"), road)
    sp, c = r["split"]["coefficients"], r["constant"]["coefficients"]
    assert sp["v^0"] == pytest.approx(400.0, abs=5.0) and sp["moving"] == pytest.approx(1000.0, abs=5.0)
    assert sp["acc"] == pytest.approx(1.0, abs=0.01)
    assert r["standing_measured_w"] == pytest.approx(400.0, abs=15.0)   # road load at v < 0.1 m/s is small, not 0
    assert 400.0 < c["v^0"] < 1400.0
    assert r["split"]["mean_abs_error"] < 0.001 < r["constant"]["mean_abs_error"]


def test_joint_choice_judges_each_grade_source_by_its_own_closed_loop_structure(monkeypatch):
    """validation.closing_the_loop_fit.grade_and_physics, choice: "sequential" takes the grade
    source whose calibrated terms cross-validate best; "joint" (the default) the one whose
    closed-loop structure (its own physical candidates) does — here a different source. The logger offset is left out
    of the grid when it cannot be estimated; the joint choice keeps the data read its way."""
    from types import SimpleNamespace

    import sumo_drvpw.fit.physical as phys
    from sumo_drvpw.validation import closing_the_loop_fit as mod

    # grade source → (CV of the calibrated terms, CV after its own physical candidates)
    table = {60.0: (0.061, 0.040), 300.0: (0.059, 0.042), "1000 m": (0.063, 0.031)}
    monkeypatch.setattr(mod, "TAU_GRID_S", (60.0, 300.0, "1000 m", mod.LOGGER_OFFSET))
    monkeypatch.setattr(mod, "logger_offset", lambda m: {"offset_mps2": float("nan"), "trips": 0,
                                                         "iqr_mps2": [float("nan")] * 2})
    read = []

    def corrected(path, vehicle, lag, acc, tau, off=None):
        assert tau != mod.LOGGER_OFFSET
        read.append(tau)
        return SimpleNamespace(tau=tau)

    def stage(m, base, name, energy="traction"):
        cv = {"mean_abs_error": table[m.tau][1], "max_abs_error": 2 * table[m.tau][1], "rmse_w": 1.0}
        return f"eq@{m.tau}", {"cv": cv, "chosen": [f"cand@{m.tau}"]}, 0.0

    monkeypatch.setattr(mod, "corrected_measured", corrected)
    monkeypatch.setattr(mod, "physical_stage", stage)
    monkeypatch.setattr(mod, "_cv_args", lambda m: (m,))
    monkeypatch.setattr(phys, "trip_cv", lambda m, terms, energy="traction": {"mean_abs_error": table[m.tau][0],
                                                           "max_abs_error": 0.1, "rmse_w": 1.0})
    tau, m, eq, sel, _ = mod.grade_and_physics("train.parquet", "car", 0.0, ["acc", "grade"], None, "x",
                                               choice="sequential")
    assert tau["tau_s"] == 300.0 and m.tau == 300.0 and eq == "eq@300.0"
    read.clear()
    tau, m, eq, sel, _ = mod.grade_and_physics("train.parquet", "car", 0.0, ["acc", "grade"], None, "x")
    assert tau["joint"] and tau["tau_s"] == "1000 m" and m.tau == "1000 m" and eq == "eq@1000 m"
    assert sel["chosen"] == ["cand@1000 m"]
    assert read == [60.0, 300.0, "1000 m"]                  # every source once, no logger offset
    assert {t: c["chosen"] for t, c in tau["cv"].items()} == {t: [f"cand@{t}"] for t in table}
    assert {t: c["mean_abs_error"] for t, c in tau["cv"].items()} == {t: v[1] for t, v in table.items()}
