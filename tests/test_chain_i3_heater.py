"""validation.chain_i3_heater: estimators of the i3's heater load where its V·I is not logged
(planted signals whose true heater power is known), and the committed report's invariants."""

import json
from pathlib import Path

import numpy as np
import pytest

from sumo_drvpw.validation.chain_common import KWH
from sumo_drvpw.validation.chain_i3_heater import _energy_cv, heat_balance_k, heater_estimate, hold_share


def test_heat_balance_recovers_a_planted_air_flow():
    """heater = ṁ·c_p·(T_hx − T_air)⁺ with ṁ·c_p = 48 W/K (0.048 kg/s of air at 1005 J/(kg·K)):
    k comes back within 1 %; samples outside the mask (another heater) and NaN do not count."""
    rng = np.random.default_rng(3)
    n = 20000
    air = rng.uniform(-5, 25, n)
    hx = air + rng.uniform(-15, 50, n)
    heater = 48.0 * np.maximum(hx - air, 0.0) + rng.normal(0, 50, n)
    mask = np.arange(n) < n // 2
    heater[~mask] = 5000.0
    hx[5] = np.nan
    assert heat_balance_k(hx, air, heater, mask) == pytest.approx(48.0, rel=0.01)
    h, p = heater_estimate("heat_balance", {"can": hx * 0, "req": hx * 0, "hx": hx, "air": air, "vi": heater}, mask)
    assert p["k_w_per_k"] == pytest.approx(48.0, rel=0.01)
    assert np.all(h >= 0) and np.isfinite(h).all()


def test_min_of_can_and_request_drops_a_held_can_value_and_an_over_request():
    """True draw: 1.5 kW for the first 100 s, then off. CAN holds its last 1.5 kW after the heater
    stops (a stale message); the request asks 7 kW while the heater draws 1.5 kW. Each alone
    books too much; their minimum is the draw."""
    dt = 0.1
    t = np.arange(0, 300, dt)
    true = np.where(t < 100, 1500.0, 0.0)
    can = np.full(t.size, 1500.0)                       # held after the heater stops
    req = np.where(t < 100, 7000.0, 0.0)                # asks more than the heater draws
    cols = {"can": can, "req": req, "hx": t * np.nan, "air": t * np.nan, "vi": true}
    e = {k: float(heater_estimate(k, cols, np.ones(t.size, bool))[0].sum() * dt) / KWH
         for k in ("none", "can", "req", "min_can_req")}
    truth = float(true.sum() * dt) / KWH
    assert e["min_can_req"] == pytest.approx(truth, rel=1e-9)
    assert e["can"] == pytest.approx(3 * truth, rel=1e-6) and e["req"] == pytest.approx(7 / 1.5 * truth, rel=1e-6)
    assert e["none"] == 0.0
    with pytest.raises(ValueError):
        heater_estimate("bogus", cols, np.ones(t.size, bool))


def test_hold_share_counts_positive_values_held_at_least_the_hold_time():
    """A 300 s trip at 10 Hz: 1480 W held 90 s counts (0.3), 500 W held 50 s does not, zero held
    120 s does not; a varying value never counts."""
    dt = np.full(3000, 0.1)
    v = np.concatenate([np.full(900, 1480.0), np.full(500, 500.0), np.zeros(1200), np.arange(400.0) + 1])
    trips = np.array(["T1"] * 3000)
    assert hold_share(v, trips, dt)["T1"] == pytest.approx(0.3, abs=1e-9)
    assert hold_share(np.arange(3000.0) + 1, trips, dt)["T1"] == 0.0


def test_heater_energy_cv_scores_estimators_on_held_out_logged_trips():
    """Ten logged trips whose heater obeys a planted heat balance (40 W/K) and whose CAN reads
    V·I + 200 W: held out, the heat balance's heater energy is exact, CAN's is off by 200 W ×
    the trip's time, 'none' by the trip's whole heater energy; trips without V·I never enter."""
    rng = np.random.default_rng(7)
    per, dt = 1200, 1.0
    ids = [f"T{i:02d}" for i in range(12)]
    trips = np.repeat(ids, per)
    air = rng.uniform(0, 10, trips.size)
    hx = air + rng.uniform(0, 40, trips.size)
    vi = 40.0 * (hx - air)
    logged = ~np.isin(trips, ["T10", "T11"])
    vi_col = np.where(logged, vi, 9e9)          # nonsense where unlogged: must stay out
    cols = {"can": vi + 200.0, "req": vi, "hx": hx, "air": air, "vi": vi_col}
    cv = _energy_cv(cols, logged, trips, np.full(trips.size, dt), ids)
    assert cv["heat_balance"]["mean_abs_kwh"] == pytest.approx(0.0, abs=1e-9)
    assert cv["req"]["mean_abs_kwh"] == pytest.approx(0.0, abs=1e-9)
    assert cv["can"]["mean_kwh"] == pytest.approx(200.0 * per * dt / KWH, rel=1e-9)
    mean_heater = np.mean([vi[trips == t].sum() * dt / KWH for t in ids[:10]])
    assert cv["none"]["mean_abs_kwh"] == pytest.approx(mean_heater, rel=1e-9)


def test_committed_heater_study_repeats_the_pipelines_own_folds():
    """docs/energy-chain-validation.json: the heater study's 'none' estimator is the pipeline
    itself, fold for fold — its 2-fold and 5-fold mean |errors| are the headline ones (the
    study refits the same folds), the bound only adds energy (a load ≥ 0) and only on trips
    without V·I, and trips with V·I are left as they are by every estimator."""
    ref = json.loads((Path(__file__).resolve().parents[1] / "docs" / "energy-chain-validation.json")
                     .read_text(encoding="utf-8"))["bmw_i3"]
    h = ref["heater"]["protocols"]
    assert h["2-fold"]["none"]["pipeline"]["mean_abs_error"] == pytest.approx(ref["mean_abs_error"], abs=1e-9)
    assert h["5-fold"]["none"]["pipeline"]["mean_abs_error"] == pytest.approx(ref["kfold"]["mean_abs_error"], abs=1e-9)
    flagged = set(ref["heater"]["deficit_kwh"])
    assert len(flagged) == ref["n_flagged"]
    for proto in h.values():
        none = proto["none"]["pipeline"]["errors"]
        for t, err in proto["bound"]["errors"].items():
            assert err >= none[t] - 1e-12 if t in flagged else err == pytest.approx(none[t], abs=1e-12)
        for e in ref["heater"]["estimators"]:
            for t, err in proto[e]["pipeline"]["errors"].items():
                if t not in flagged:
                    assert err == pytest.approx(none[t], abs=1e-12)


def test_the_heater_study_uses_chain_i3s_public_helpers():
    """chain_i3_heater reuses chain_i3's road-load fit and recuperation limit through public
    names (it imported _road_load, _limit_w and _limited across modules)."""
    import ast

    import sumo_drvpw.validation.chain_i3_heater as mod

    tree = ast.parse(Path(mod.__file__).read_text(encoding="utf-8"))
    private = [a.name for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and (n.module or "").startswith("sumo_drvpw")
               for a in n.names if a.name.startswith("_")]
    assert not private, private
