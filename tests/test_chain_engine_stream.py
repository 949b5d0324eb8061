"""A heavy engine's fuel chain calibrated streamed (fit/chain_stream.py) as in memory
(fit/chain_fuel.py): an equation that declares a moving zero-output fuel
(``moving_idle_fuel_power_w``, fitted) and a rated output (``engine_max_w``, kept) gives the same
equation file and report through ``--engine local`` as through ``--engine memory``, to 1e-9
relative, on a generated truck log with both planted (read in batches smaller than a trip).

Why: the streamed calibration refused both keys (exit 2), so a log too large for memory could
not be calibrated for the engine the in-memory path fits."""

from __future__ import annotations

import json
import tomllib
from functools import partial

import numpy as np
import pandas as pd
import pytest

import corpus
import sumo_drvpw.fit.engine as engine_mod
from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.model.chain_toml import chain_from_dict
from sumo_drvpw.model.constants import FUELS

RTOL = 1e-9
IDLE_W, MOVING_W, ETA, CAP_W = 8_000.0, 30_000.0, 0.40, 300_000.0
MASS_KG, V1, V3 = 30_000.0, 1800.0, 4.0


def _truck_log(tmp_path, seed=5):
    """Trips of a 30-t truck at 1 Hz (accelerate, cruise, brake, stand 60 s) with the fuel a
    planted engine burns — idle standing, :data:`MOVING_W` moving at zero output, capped at
    :data:`CAP_W` — on the driving power of the road load the equation file declares, 2 % noise;
    the equation file declares both engine keys (the moving fuel to fit, the rating kept)."""
    rng = np.random.default_rng(seed)
    v = np.concatenate([np.concatenate([np.arange(0.0, top, rng.uniform(0.25, 0.5)), np.full(int(rng.uniform(60, 300)), top),
                                        np.arange(top, 0.0, -rng.uniform(0.6, 1.2)), np.zeros(60)])
                        for top in rng.uniform(10.0, 27.0, 30)])
    t = np.arange(v.size, dtype=float)
    p = MASS_KG * np.gradient(v, t) * v + V1 * v + V3 * v ** 3
    ch = chain_from_dict({"predicts": "fuel", "fuel": "gasoline", "marginal_efficiency": ETA, "idle_fuel_power_w": IDLE_W,
                          "engine_off_below_w": -np.inf, "moving_idle_fuel_power_w": MOVING_W, "engine_max_w": CAP_W})
    fuel_w = ch.evaluate(p, v)["power_w"] * (1.0 + 0.02 * rng.standard_normal(v.size))
    gas = FUELS["gasoline"]
    pd.DataFrame({"time_s": t, "speed_mps": v, "mass_kg": MASS_KG,
                  "fuel_rate_lph": fuel_w / (gas["lhv_j_per_kg"] * gas["density_kg_per_l"]) * 3600.0}
                 ).to_parquet(tmp_path / "truck.parquet", row_group_size=1500)
    (tmp_path / "rl.toml").write_text(f'[equation]\nname = "rl"\n[terms]\nacc = 1.0\nv1 = {V1}\nv3 = {V3}\n'
                                      '[chain]\npredicts = "fuel"\nmoving_idle_fuel_power_w = 0.0\n'
                                      f'engine_max_w = {CAP_W}\n', encoding="utf-8")
    return tmp_path / "truck.parquet", tmp_path / "rl.toml", float(np.mean(p > CAP_W))


def _calibrate(monkeypatch, capsys, log, eq, out, engine, *extra, rows=2000):
    monkeypatch.setattr(engine_mod, "run", partial(engine_mod.run, rows=rows))
    rc = cli_main(["calibrate", str(log), "--target", "fuel", "--equation", str(eq), "--name", "truck",
                   "--engine", engine, "--out", str(out), "--report", str(out.with_suffix("")), *extra])
    cap = capsys.readouterr()
    monkeypatch.undo()
    assert rc == 0, cap.err
    doc = tomllib.loads(out.read_text(encoding="utf-8"))
    doc.get("provenance", {}).pop("date", None)
    report = json.loads((out.with_suffix("") / "report.json").read_text(encoding="utf-8"))
    return doc, report, [ln.replace(str(out), "OUT") for ln in cap.out.splitlines() if not ln.startswith("wrote")]


def test_streamed_fits_the_moving_idle_and_keeps_the_rating_as_in_memory(tmp_path, monkeypatch, capsys):
    log, eq, beyond = _truck_log(tmp_path)
    assert beyond > 0.01  # the planted truck reaches its rated output
    ref, rep_m, said_m = _calibrate(monkeypatch, capsys, log, eq, tmp_path / "memory.toml", "memory")
    got, rep_l, said_l = _calibrate(monkeypatch, capsys, log, eq, tmp_path / "local.toml", "local")
    corpus.assert_close_documents(ref, got, RTOL)
    rep_l["settings"].pop("percentiles")
    rep_m["settings"].pop("percentiles", None)
    corpus.assert_close_documents(rep_m, rep_l, RTOL)
    assert said_l == said_m
    ch = got["chain"]
    assert ch["engine_max_w"] == CAP_W  # kept as declared (η_t 1, no auxiliaries: the same at the wheels)
    for key, want in (("idle_fuel_power_w", IDLE_W), ("moving_idle_fuel_power_w", MOVING_W),
                      ("marginal_efficiency", ETA)):  # what was planted, through the streamed fit
        assert ch[key] == pytest.approx(want, rel=0.05), key


def test_a_charge_sustaining_engine_s_rating_is_the_one_it_was_fitted_with(tmp_path, monkeypatch, capsys):
    """A hybrid's engine that stops below 4 kW (charge-sustaining: its 2-kW auxiliary draw paid at
    the margin, a parameter of the fit) with a 40-kW rated output the equation file declares: the
    design caps the driving power at (40 − 2) kW, and the written chain, which caps P + P_aux, has
    the rating 38 kW + the fitted auxiliary power — 40 kW, the planted — so it books what was
    fitted: its RMSE the noise's, its energy the log's, in memory and streamed alike (before, the
    chain kept 38 kW, subtracting the auxiliary power twice: RMSE 1.7 kW against 30 W, 1.1 % of
    the fuel missing on a random log; the streamed fit, whose figures come from the design, then
    disagreed with the in-memory one)."""
    rng = np.random.default_rng(4)
    v = np.concatenate([np.concatenate([np.arange(0.0, top, 1.2), np.full(int(rng.uniform(60, 300)), top),
                                        np.arange(top, 0.0, -1.0), np.zeros(30)]) for top in rng.uniform(8.0, 30.0, 30)])
    t = np.arange(v.size, dtype=float)
    mass, v1, v3 = 1500.0, 150.0, 0.4
    p = mass * np.gradient(v, t) * v + v1 * v + v3 * v ** 3
    ch = chain_from_dict({"predicts": "fuel", "fuel": "gasoline", "marginal_efficiency": 0.35, "idle_fuel_power_w": 3000.0,
                          "engine_off_below_w": 4000.0, "charge_sustaining": True, "aux_power_w": 2000.0,
                          "engine_max_w": 40e3})
    fuel_w = ch.evaluate(p, v)["power_w"] + 30.0 * rng.standard_normal(v.size)
    assert np.mean((p > 38e3) & (p > 0)) > 0.005  # the demand reaches the rating
    gas = FUELS["gasoline"]
    pd.DataFrame({"time_s": t, "speed_mps": v, "mass_kg": mass,
                  "fuel_rate_lph": fuel_w / (gas["lhv_j_per_kg"] * gas["density_kg_per_l"]) * 3600.0}
                 ).to_parquet(tmp_path / "hev.parquet", row_group_size=1500)
    eq = tmp_path / "rl.toml"
    eq.write_text(f'[equation]\nname = "rl"\n[terms]\nacc = 1.0\nv1 = {v1}\nv3 = {v3}\n[chain]\npredicts = "fuel"\n'
                  'aux_power_w = 2000.0\nengine_max_w = 40000.0\n', encoding="utf-8")
    extra = ("--engine-off", "4000")
    ref, rep_m, said_m = _calibrate(monkeypatch, capsys, tmp_path / "hev.parquet", eq, tmp_path / "memory.toml", "memory", *extra)
    got, rep_l, said_l = _calibrate(monkeypatch, capsys, tmp_path / "hev.parquet", eq, tmp_path / "local.toml", "local", *extra)
    corpus.assert_close_documents(ref, got, RTOL)
    assert said_l == said_m
    ch = got["chain"]
    assert ch["charge_sustaining"] and ch["aux_power_w"] == pytest.approx(2000.0, rel=0.02)
    assert ch["engine_max_w"] == pytest.approx(40e3, rel=1e-3)
    assert ch["metrics"]["rmse_w"] == pytest.approx(30.0, rel=0.1)
    assert ch["metrics"]["energy_ratio"] == pytest.approx(1.0, abs=1e-4)
