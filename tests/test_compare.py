"""Tests of sumo_drvpw.fit.compare, plots and report (paper Table 3, Fig. 4, 5, 8, 9, 10)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from sumo_drvpw.fit.compare import (compare, energy_shares, error_term_correlation, metrics,
                                speed_bins)
from sumo_drvpw.model.constants import G, HEAVY_LOAD_W, HIGH_SPEED_MPS, KMH
from sumo_drvpw.model.equations import Equation
from sumo_drvpw.errors import UserError
from sumo_drvpw.report.figures import subsample_index
from sumo_drvpw.report.comparison import FIGURES, write_comparison_report
from sumo_drvpw.model.terms import Inputs

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
TRUTH = {"acc": 1.0, "grade": 1.0, "aero": 0.9, "roll": 0.012}


def _inputs(v, a, theta=None, mass=1625.0):
    v = np.asarray(v, dtype=float)
    n = v.size
    return Inputs(v=v, a=np.asarray(a, dtype=float),
                  theta=np.zeros(n) if theta is None else np.asarray(theta, dtype=float),
                  wind=np.zeros(n), mass=np.full(n, mass), rho=np.full(n, 1.2))


def _drive(n=6000, seed=1):
    """Synthetic samples: speeds 0–160 km/h, accelerations ±, small grades."""
    rng = np.random.default_rng(seed)
    v = rng.uniform(0.0, 160.0 * KMH, n)
    a = rng.normal(0.0, 0.7, n)
    theta = rng.normal(0.0, 0.02, n)
    return _inputs(v, a, theta)


# ----------------------------------------------------------------- metrics by hand

def test_metrics_hand_calculated_five_samples():
    # measured 10, 20, 30, 60, 80 kW; predicted 12, 18, 33, 55, 85 kW
    # error 2, −2, 3, −5, 5 kW → bias 0.6 kW, MAE 3.4 kW, SSE 67 kW², RMSE √13.4 kW
    # mean 40 kW, SST 900+400+100+400+1600 = 3400 kW² → R² = 1 − 67/3400
    # light (10, 20, 30): SSE 17, mean 20, SST 200 → R² = 0.915; heavy: 2 samples → NaN
    meas = np.array([10, 20, 30, 60, 80]) * 1e3
    pred = np.array([12, 18, 33, 55, 85]) * 1e3
    m = metrics(pred, meas)
    assert m["n"] == 5 and m["n_light"] == 3 and m["n_heavy"] == 2
    assert m["bias_w"] == pytest.approx(600.0)
    assert m["mae_w"] == pytest.approx(3400.0)
    assert m["rmse_w"] == pytest.approx(math.sqrt(13.4) * 1e3)
    assert m["r2"] == pytest.approx(1.0 - 67.0 / 3400.0)
    assert m["r2_light"] == pytest.approx(0.915)
    assert math.isnan(m["r2_heavy"])  # < 3 samples
    assert m["rmse_light_w"] == pytest.approx(math.sqrt(17.0 / 3.0) * 1e3)
    assert m["rmse_heavy_w"] == pytest.approx(5e3)  # errors −5, +5 kW
    assert m["bias_light_w"] == pytest.approx(1e3) and m["bias_heavy_w"] == pytest.approx(0.0)


def test_metrics_heavy_subset_uses_its_own_mean_and_50kw_is_heavy():
    # heavy: measured 50, 60, 70 kW (exactly 50 kW counts as heavy), predicted 52, 58, 70
    # own mean 60: SST = 100+0+100 = 200, SSE = 4+4+0 = 8 → R² = 0.96
    meas = np.array([5, 10, 15, 50, 60, 70]) * 1e3
    pred = np.array([5, 10, 15, 52, 58, 70]) * 1e3
    m = metrics(pred, meas)
    assert m["n_heavy"] == 3 and m["n_light"] == 3
    assert m["r2_heavy"] == pytest.approx(0.96)
    assert m["r2_light"] == pytest.approx(1.0)
    # a constant offset c: centred R² = 1 − n·c²/Σ(m − m̄)²; the uncentred no-intercept
    # R² would divide by Σm² instead and read much closer to 1
    off = metrics(meas + 5e3, meas)
    sst = float(np.sum((meas - meas.mean()) ** 2))
    assert off["r2"] == pytest.approx(1.0 - 6 * 5e3 ** 2 / sst)
    assert off["bias_w"] == pytest.approx(5e3) and off["rmse_w"] == pytest.approx(5e3)


def test_r2_corr_is_blind_to_scale_and_offset_but_r2_is_not():
    meas = np.array([10, 20, 30, 40, 60, 70, 90]) * 1e3
    pred = 2.0 * meas + 5e3
    m = metrics(pred, meas)
    assert m["r2_corr"] == pytest.approx(1.0)
    assert m["r2_corr_light"] == pytest.approx(1.0) and m["r2_corr_heavy"] == pytest.approx(1.0)
    # centred R² by hand: error = meas + 5 kW; SSE = Σ(m + 5)², SST = Σ(m − m̄)²
    sse = float(np.sum((meas + 5e3) ** 2))
    sst = float(np.sum((meas - meas.mean()) ** 2))
    assert m["r2"] == pytest.approx(1.0 - sse / sst)
    assert m["r2"] < 0.0


def test_metrics_centred_r2_can_be_negative_and_ignores_nan_pairs():
    meas = np.array([1.0, 2.0, 3.0, 4.0]) * 1e3
    m = metrics(-meas, meas)  # worse than the mean
    assert m["r2"] < 0.0
    m2 = metrics(np.array([1e3, np.nan, 3e3, 4e3, 5e3]), np.array([1e3, 2e3, 3e3, np.inf, 5e3]))
    assert m2["n"] == 3 and m2["rmse_w"] == 0.0


def test_metrics_rejects_length_mismatch():
    with pytest.raises(UserError, match="samples"):
        metrics(np.zeros(3), np.zeros(4))


# powers at 1 mW resolution: a spread of 1e-284 W would underflow SST to zero
power_arrays = arrays(np.float64, st.integers(3, 60),
                      elements=st.floats(-1e5, 1.5e5, allow_nan=False,
                                         allow_subnormal=False).map(lambda w: round(w, 3)))


@settings(max_examples=60, deadline=None)
@given(power_arrays, st.data())
def test_metrics_properties(meas, data):
    noise = data.draw(arrays(np.float64, meas.size,
                             elements=st.floats(-3e4, 3e4, allow_nan=False,
                                                allow_subnormal=False)))
    pred = meas + noise
    m = metrics(pred, meas)
    # light and heavy partition the samples
    assert m["n_light"] + m["n_heavy"] == m["n"] == meas.size
    assert m["n_heavy"] == int((meas >= HEAVY_LOAD_W).sum())
    # RMSE ≥ MAE ≥ |bias| (Jensen / triangle inequality)
    assert m["rmse_w"] >= m["mae_w"] * (1 - 1e-12) - 1e-9
    assert m["mae_w"] >= abs(m["bias_w"]) * (1 - 1e-12) - 1e-9
    # invariance to sample order
    perm = np.random.default_rng(0).permutation(meas.size)
    mp = metrics(pred[perm], meas[perm])
    for k, v in m.items():
        if isinstance(v, float) and math.isnan(v):
            assert math.isnan(mp[k])
        else:
            assert mp[k] == pytest.approx(v, rel=1e-9, abs=1e-6)
    # a perfect prediction: R² = 1 wherever defined, RMSE = 0
    p = metrics(meas, meas)
    assert p["rmse_w"] == 0.0 and p["bias_w"] == 0.0
    if np.ptp(meas) > 0:
        assert p["r2"] == 1.0
    if m["r2"] == m["r2"]:  # R² ≤ 1 always
        assert m["r2"] <= 1.0 + 1e-12


# ----------------------------------------------------------------- energy shares

def test_energy_shares_hand_calculated():
    # v = 10 m/s, m = 1000 kg, a = 1, 0, −1, −2 m/s², flat road; acc coef 1, roll 0.01
    # acc power 10 000, 0, −10 000, −20 000 W; roll power 0.01·1000·g·10 = 98.1·g·... W
    # traction (total > 0) only in samples 0 and 1; Δt = 0.5, 2, 1, 1 s
    x = _inputs([10.0] * 4, [1.0, 0.0, -1.0, -2.0], mass=1000.0)
    eq = Equation("x", {"acc": 1.0, "roll": 0.01})
    roll_w = 0.01 * 1000.0 * G * 10.0
    meas = np.array([11000.0, 1000.0, -9000.0, -19000.0])
    dt = np.array([0.5, 2.0, 1.0, 1.0])
    comp = compare(meas, x, [eq], dt_s=dt)
    r = comp.results["x"]
    e_acc = 10000.0 * 0.5
    e_roll = roll_w * 0.5 + roll_w * 2.0
    assert r.energy_j["acc"] == pytest.approx(e_acc)
    assert r.energy_j["roll"] == pytest.approx(e_roll)
    assert r.energy_j["grade"] == 0.0 and r.energy_j["aero"] == 0.0
    assert r.energy_j["total"] == pytest.approx(e_acc + e_roll)
    assert r.energy_share["acc"] == pytest.approx(e_acc / (e_acc + e_roll))
    assert r.energy_share["roll"] == pytest.approx(e_roll / (e_acc + e_roll))
    assert sum(r.energy_share.values()) == pytest.approx(1.0)
    # measured traction energy: 11 000·0.5 + 1000·2 J
    assert comp.measured_traction_energy_j == pytest.approx(7500.0)
    assert r.traction_energy_ratio == pytest.approx((e_acc + e_roll) / 7500.0)
    # dt None means 1 s each
    r1 = compare(meas, x, [eq]).results["x"]
    assert r1.energy_j["acc"] == pytest.approx(10000.0)
    assert r1.energy_j["roll"] == pytest.approx(2 * roll_w)


@settings(max_examples=40, deadline=None)
@given(arrays(np.float64, (4, 12), elements=st.floats(-5e4, 5e4, allow_nan=False,
                                                       allow_subnormal=False)),
       arrays(np.float64, 12, elements=st.floats(0.01, 2.0)))
def test_energy_shares_sum_to_one(p, dt):
    cats = dict(zip(("acc", "grade", "aero", "roll"), p))
    energy, share = energy_shares(cats, dt)
    total = p.sum(axis=0)
    if energy["total"] > 1e-6 * np.abs(p).sum() * dt.max():
        assert sum(share.values()) == pytest.approx(1.0, rel=1e-9)
        assert energy["total"] == pytest.approx(float(total[total > 0] @ dt[total > 0]),
                                                rel=1e-9)


# --------------------------------------------------------- missing aero term (Fig. 8/9)

def test_truth_equation_is_perfect():
    x = _drive()
    truth = Equation("truth", TRUTH)
    comp = compare(truth.power(x), x, [truth])
    m = comp.results["truth"].metrics
    assert m["r2"] == pytest.approx(1.0) and m["rmse_w"] == pytest.approx(0.0, abs=1e-9)
    assert m["r2_light"] == pytest.approx(1.0) and m["r2_heavy"] == pytest.approx(1.0)


def test_missing_aero_term_error_grows_with_speed_and_tracks_aero_power():
    x = _drive()
    truth = Equation("truth", TRUTH)
    no_aero = Equation("no_aero", {k: c for k, c in TRUTH.items() if k != "aero"})
    meas = truth.power(x)
    comp = compare(meas, x, [truth, no_aero], dt_s=0.125, reference="truth")
    r = comp.results["no_aero"]
    true_aero = truth.category_powers(x)["aero"]
    # error is exactly minus the true aero power: underprediction that grows with speed
    np.testing.assert_allclose(comp.error_w("no_aero"), -true_aero, atol=1e-6)
    means = [b["mean_w"] for b in r.speed_bins if b["n"] > 0]
    assert len(means) >= 15
    assert all(np.diff(means) < 0)  # more negative with every 10 km/h
    hs = r.high_speed
    hi = x.v >= HIGH_SPEED_MPS
    assert hs["n"] == int(hi.sum())
    assert hs["mean_w"] == pytest.approx(-true_aero[hi].mean())
    assert hs["mean_w"] < hs["mean_below_w"] < 0
    assert r.metrics["r2_heavy"] < comp.results["truth"].metrics["r2_heavy"]
    # against the truth's term powers the error is the aero term, one for one:
    # r = −1 and partial slope −1 for aero; the other terms carry no error of their own
    rc = r.error_reference_correlation
    assert rc["aero"]["r"] == pytest.approx(-1.0, abs=1e-9)
    assert rc["aero"]["partial_slope"] == pytest.approx(-1.0, abs=1e-6)
    for c in ("acc", "grade", "roll"):
        assert abs(rc[c]["partial_slope"]) < 1e-6
        assert abs(rc[c]["r"]) < abs(rc["aero"]["r"])
    # its own aero power is zero: no signal there; its speed-dependent roll term absorbs it
    own = r.error_term_correlation
    assert math.isnan(own["aero"]["r"]) and math.isnan(own["aero"]["slope"])
    assert own["roll"]["r"] < -0.5
    # the missing aero energy shows in the shares and the energy ratio
    assert r.energy_share["aero"] == 0.0
    assert r.traction_energy_ratio < comp.results["truth"].traction_energy_ratio


def test_partial_slope_is_relative_coefficient_error():
    # aero 0.6 where truth is 0.9: error = −0.3·aero basis = −0.5 × own aero power
    x = _drive()
    truth = Equation("truth", TRUTH)
    low = Equation("low_aero", {**TRUTH, "aero": 0.6})
    comp = compare(truth.power(x), x, [low])
    c = comp.results["low_aero"].error_term_correlation
    assert c["aero"]["partial_slope"] == pytest.approx(-0.5, abs=1e-6)
    assert c["aero"]["slope"] == pytest.approx(-0.5, abs=1e-6)
    assert c["aero"]["r"] == pytest.approx(-1.0, abs=1e-9)
    assert abs(c["roll"]["partial_slope"]) < 1e-6


def test_error_term_correlation_hand_example():
    # error = 2·p_acc + 1: r = 1, slope 2; p_grade constant → NaN
    p = np.array([1.0, 2.0, 4.0, 8.0])
    out = error_term_correlation(2 * p + 1, {"acc": p, "grade": np.zeros(4)})
    assert out["acc"]["r"] == pytest.approx(1.0) and out["acc"]["slope"] == pytest.approx(2.0)
    assert math.isnan(out["grade"]["r"])


# --------------------------------------------------------------------- speed bins

def test_speed_bins_hand_example():
    v = np.array([0.0, 5.0, 9.99, 10.0, 25.0, 39.9]) * KMH
    err = np.array([1.0, 2.0, 3.0, 10.0, -4.0, 7.0])
    bins = speed_bins(err, v)
    assert [b["lo_kmh"] for b in bins] == pytest.approx([0.0, 10.0, 20.0, 30.0])
    assert [b["n"] for b in bins] == [3, 1, 1, 1]
    assert bins[0]["mean_w"] == pytest.approx(2.0) and bins[0]["median_w"] == pytest.approx(2.0)
    assert bins[0]["p5_w"] == pytest.approx(1.1) and bins[0]["p95_w"] == pytest.approx(2.9)
    assert bins[0]["rmse_w"] == pytest.approx(math.sqrt(14.0 / 3.0))
    assert bins[1]["mean_w"] == 10.0 and bins[2]["mean_w"] == -4.0
    assert sum(b["n"] for b in bins) == v.size


def test_speed_bins_empty_bin_is_reported_with_nan():
    bins = speed_bins(np.array([1.0, 2.0]), np.array([1.0, 35.0]) * KMH)
    assert [b["n"] for b in bins] == [1, 0, 0, 1]
    assert math.isnan(bins[1]["mean_w"])


# ------------------------------------------------------------------ input checks

def test_compare_rejects_bad_input():
    x = _inputs([1.0, 2.0, 3.0], [0.0, 0.0, 0.0])
    eq = Equation("x", {"roll": 0.01})
    with pytest.raises(UserError, match="samples"):
        compare(np.zeros(2), x, [eq])
    with pytest.raises(UserError, match="row 1"):
        compare(np.array([0.0, np.nan, 0.0]), x, [eq])
    with pytest.raises(UserError, match="unique"):
        compare(np.zeros(3), x, [eq, Equation("x", {"acc": 1.0})])
    with pytest.raises(UserError, match="dt_s"):
        compare(np.zeros(3), x, [eq], dt_s=np.array([1.0, -1.0, 1.0]))
    with pytest.raises(UserError, match="reference"):
        compare(np.zeros(3), x, [eq], reference="nope")


def test_inputs_not_modified():
    x = _drive(200)
    meas = Equation("t", TRUTH).power(x)
    before = (x.v.copy(), meas.copy())
    compare(meas, x, [Equation("e", {"acc": 1.0})])
    np.testing.assert_array_equal(x.v, before[0])
    np.testing.assert_array_equal(meas, before[1])


# ----------------------------------------------------------------------- report

def test_subsample_index():
    assert np.array_equal(subsample_index(10, 50), np.arange(10))
    idx = subsample_index(1_000_000, 50_000)
    assert idx.size == 50_000 and np.all(np.diff(idx) > 0) and idx[-1] < 1_000_000


def test_report_files_and_keys(tmp_path):
    x = _drive(3000)
    rng = np.random.default_rng(3)
    truth = Equation("truth", TRUTH, std_err={"acc": 0.001, "aero": 0.01})
    no_aero = Equation("no_aero", {k: c for k, c in TRUTH.items() if k != "aero"})
    meas = truth.power(x) + rng.normal(0.0, 1500.0, len(x))
    comp = compare(meas, x, [truth, no_aero], dt_s=0.125, reference="truth")
    out = tmp_path / "rep"
    write_comparison_report(comp, out, "Synthetic check", {"log": "synthetic.parquet",
                                                           "vehicle": "prius3"})
    doc = json.loads((out / "report.json").read_text(encoding="utf-8"))
    assert doc["n_samples"] == len(x)
    assert doc["context"]["vehicle"] == "prius3" and doc["title"] == "Synthetic check"
    for name in ("truth", "no_aero"):
        d = doc["equations"][name]
        for k in ("n", "r2", "r2_light", "r2_heavy", "rmse_w", "bias_w", "mae_w",
                  "speed_bins", "high_speed", "error_term_correlation", "energy_share",
                  "energy_j"):
            assert k in d, (name, k)
        assert d["n"] == len(x)
        assert set(d["energy_j"]) >= {"acc", "grade", "aero", "roll", "total"}
        assert sum(d["energy_share"].values()) == pytest.approx(1.0)
        assert d["r2"] == pytest.approx(comp.results[name].metrics["r2"])
    assert doc["equations"]["no_aero"]["error_term_correlation"]["aero"]["r"] is None  # NaN
    assert doc["equations"]["no_aero"]["high_speed"]["mean_w"] < -5e3
    # strict JSON: NaN written as null
    json.loads((out / "report.json").read_text(encoding="utf-8"), parse_constant=lambda c: 1 / 0)
    md = (out / "report.md").read_text(encoding="utf-8")
    assert md.startswith("# Synthetic check")
    assert "R² ≥ 50 kW" in md and "80 km/h" in md and "no_aero" in md
    assert "underpredicts" in md  # no_aero above 80 km/h
    assert "± 0.001" in md  # standard error from Equation.std_err
    for fname in FIGURES:
        p = out / fname
        assert p.is_file() and p.stat().st_size > 1000, fname
        assert p.read_bytes()[:8] == PNG_MAGIC, fname
        assert f"]({fname})" in md


def test_two_files_of_one_equation_name_are_refused_naming_both(tmp_path):
    """Found by the metamorphic sweep: a copy of an equation file under another file name was
    refused as "the same equation name given twice: ['eq_base']", naming neither file."""
    from sumo_drvpw.data.measured import resolve_equations

    body = '[equation]\nname = "eq_base"\n[terms]\nacc = 1.0\nv3 = 0.35\n'
    a, b = tmp_path / "a.toml", tmp_path / "copy.toml"
    a.write_text(body, encoding="utf-8")
    b.write_text(body, encoding="utf-8")
    with pytest.raises(UserError) as e:
        resolve_equations([str(a), str(b)])
    msg = str(e.value)
    assert str(a) in msg and str(b) in msg and "'eq_base'" in msg


@pytest.mark.parametrize("predicts", ["fuel", "battery"])
def test_which_term_errs_reads_a_chain_target_in_its_own_watts(predicts):
    """The measured target is a chain of the true driving power, whose aero term is 1.5× the
    equation's; the equation carries the same chain. The error, in the target's watts, is
    regressed on each term as it reaches the target (the chain's slope times the term), so
    aero's partial slope reads −0.5 (“the data ask for 1.5× that term”) as at the wheels.
    Regressed on the wheel powers, a fuel chain's 1/η_m (≈ 2.9) came out in it (−1.43; a
    rehearsal read 'roll' −9.5 on a petrol car's fuel)."""
    from sumo_drvpw.model.chain import EnergyChain
    from sumo_drvpw.model.equations import Equation

    x = _drive()
    terms = {"acc": 1.0, "grade": 1.0, "aero_rho": 0.3, "roll": 0.01}
    chain = (EnergyChain(predicts="fuel", idle_fuel_power_w=3000.0, marginal_efficiency=0.35,
                         engine_off_below_w=-np.inf)
             if predicts == "fuel" else EnergyChain(predicts="battery", traction_efficiency=0.9,
                                                    recuperation_efficiency=0.9))
    eq = Equation("eq", terms, chain=chain)
    true = Equation("true", {**terms, "aero_rho": 0.45}, chain=chain)
    meas = chain.target_power(true.power(x), x.v, x.signals, None, x.a, x.theta)
    res = compare(meas, x, [eq], target=predicts).results["eq"]
    assert res.error_term_correlation["aero"]["partial_slope"] == pytest.approx(-0.5, abs=0.02)
    for c in ("acc", "roll"):
        assert abs(res.error_term_correlation[c]["partial_slope"]) < 0.05  # (the sign of P near 0 differs)


def test_a_fuel_comparison_with_the_hybrid_battery_says_which_side_is_corrected(tmp_path):
    """With the hybrid battery's V·I each chain's predicted fuel has the battery's energy
    change taken off while 'measured' is the logged flow; report.md said nothing of it (a
    rehearsal's Prius: 2.679 L measured against docs' corrected 2.625 L, 2026-11-29)."""
    from sumo_drvpw.fit.compare import compare
    from sumo_drvpw.model.chain import EnergyChain
    from sumo_drvpw.model.equations import Equation
    from sumo_drvpw.model.terms import Inputs
    from sumo_drvpw.report.comparison import write_comparison_report

    n = 400
    v = 10.0 + 3.0 * np.sin(np.arange(n) / 20.0)
    x = Inputs(v, np.gradient(v), np.zeros(n), np.zeros(n), np.full(n, 1400.0), np.full(n, 1.2))
    eq = Equation("h", {"acc": 1.0, "roll": 0.01},
                  chain=EnergyChain(predicts="fuel", idle_fuel_power_w=4000.0, marginal_efficiency=0.38,
                                    engine_off_below_w=0.0, fuel="gasoline"))
    meas = eq.chain.evaluate(eq.power(x), v)["power_w"]
    for bat, said in ((None, False), (np.full(n, 1500.0), True)):
        comp = compare(meas, x, [eq], dt_s=np.ones(n), target="fuel", battery_w=bat)
        doc = comp.to_json()
        assert ("battery_correction" in doc["settings"]) == said
        write_comparison_report(comp, tmp_path / str(said), "t")
        md = (tmp_path / str(said) / "report.md").read_text(encoding="utf-8")
        assert ("hybrid battery's energy change taken off" in md) == said
        assert "is here of the measured fuel power" in md  # (the paper's split is of the driving power)
