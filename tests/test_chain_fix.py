"""`calibrate --target battery --fix NAME=VALUE`: a chain's parameters held at known values
(fit/chain_fixed.py, cli/_fix.py), in memory and streamed.

A planted battery chain (η_t 0.88, η_r 0.66, 450 W auxiliary draw, no recuperation limit;
V·I with 150 W of noise) on four trips of tests/test_stream_chain.py's drive: holding one
parameter at its true value recovers the others within 2 %, and the streamed fit equals the
in-memory one to 1e-9 relative. Bad --fix values are refused in one line naming the option.
"""

import tomllib
from functools import partial

import numpy as np
import pandas as pd
import pytest

import corpus
import sumo_drvpw.fit.engine as engine_mod
import test_stream_chain as planted
from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.data.log import from_frame
from sumo_drvpw.model.chain import EnergyChain

RTOL = 1e-9
_RUN = engine_mod.run
ROAD = """[equation]
name = "ev_road"
[terms]
acc = 1.05
grade = 1.0
v1 = 140.0
v3 = 0.33
"""
TRUE = {"traction_efficiency": 0.88, "recuperation_efficiency": 0.66, "aux_power_w": 450.0}


@pytest.fixture(scope="module")
def fix_log(tmp_path_factory):
    d = tmp_path_factory.mktemp("chain_fix")
    rng = np.random.default_rng(21)
    df = pd.concat([planted._trip(rng, f"T{i}", 3000 + 400 * i, 10.0) for i in range(4)], ignore_index=True)
    x = from_frame(df.copy()).inputs()
    eq = planted._eq(ROAD)
    p_bat = EnergyChain(predicts="battery", **TRUE).evaluate(eq.power(x), x.v)["power_w"]
    df["battery_voltage_v"] = 355.0
    df["battery_current_a"] = (p_bat + rng.normal(0, 150.0, len(df))) / 355.0
    folder = d / "logs"
    folder.mkdir()
    df[df["trip_id"].isin(["T0", "T1"])].to_parquet(folder / "a.parquet", row_group_size=900)
    df[df["trip_id"].isin(["T2", "T3"])].to_csv(folder / "b.csv", index=False)
    (d / "road.toml").write_text(ROAD, encoding="utf-8")
    return folder, d / "road.toml"


def _calibrate(monkeypatch, capsys, log, eq, out, engine, *extra):
    monkeypatch.setattr(engine_mod, "run", partial(_RUN, rows=2000))  # every trip crosses batches
    rc = cli_main(["calibrate", str(log), "--target", "battery", "--equation", str(eq), "--out", str(out),
                   "--name", "chain", "--engine", engine, *extra])
    cap = capsys.readouterr()
    monkeypatch.undo()
    assert rc == 0, cap.err
    doc = tomllib.loads(out.read_text(encoding="utf-8"))
    doc.get("provenance", {}).pop("date", None)
    return doc, cap


@pytest.mark.parametrize("held", ["aux_power_w", "traction_efficiency", "recuperation_efficiency"])
def test_holding_one_true_value_recovers_the_others(fix_log, held, tmp_path, monkeypatch, capsys):
    log, eq = fix_log
    fix = ["--fix", f"{held}={TRUE[held]}", "--fix", "recuperation_limit_w=1e9"]  # (planted: no limit)
    ref, cm = _calibrate(monkeypatch, capsys, log, eq, tmp_path / "memory.toml", "memory", *fix)
    got, cl = _calibrate(monkeypatch, capsys, log, eq, tmp_path / "local.toml", "local", *fix)
    corpus.assert_close_documents(ref, got, RTOL)  # the same chain from both engines
    ch = got["chain"]
    assert ch[held] == TRUE[held] and ch["recuperation_limit_w"] == 1e9
    for k, v in TRUE.items():
        assert ch[k] == pytest.approx(v, rel=0.02), k
    assert ch["provenance"]["fixed"] == {held: TRUE[held], "recuperation_limit_w": 1e9}
    assert held not in ch.get("std_err", {}) and set(TRUE) - {held} <= set(ch["std_err"])
    # the console marks what was held; the streamed run read the logs once (a held limit: no quantiles)
    row = next(ln for ln in cl.out.splitlines() if ln.strip().startswith(held))
    assert " fixed " in row and cl.err.count("local engine:") == 1


def test_held_values_are_kept_and_bounds_hold(fix_log, tmp_path, monkeypatch, capsys):
    """A wrong η_t held: the auxiliary draw takes up the difference (what the road 'adds' to
    a dyno's chain), never below 0; the recuperation limit is profiled when not held."""
    log, eq = fix_log
    docs = {}
    for engine in ("memory", "local"):
        docs[engine], _ = _calibrate(monkeypatch, capsys, log, eq, tmp_path / f"{engine}.toml", engine,
                                     "--fix", "traction_efficiency=1", "--fix", "recuperation_efficiency=0.5")
    corpus.assert_close_documents(docs["memory"], docs["local"], RTOL)
    ch = docs["local"]["chain"]
    assert ch["traction_efficiency"] == 1.0 and ch["recuperation_efficiency"] == 0.5
    assert ch["aux_power_w"] > TRUE["aux_power_w"]  # η 1 books the traction losses as auxiliary power
    assert ch["aux_power_w"] >= 0 and ch.get("recuperation_limit_w", 1.0) > 0
    # compare's report marks the held values (from the TOML's [chain.provenance] fixed)
    assert cli_main(["compare", str(log), "--equation", str(tmp_path / "local.toml"), "--target", "battery",
                     "--out", str(tmp_path / "cmp")]) == 0
    md = (tmp_path / "cmp" / "report.md").read_text(encoding="utf-8")
    assert "| `traction_efficiency` | 1 (fixed) |" in md and "| `recuperation_efficiency` | 0.5 (fixed) |" in md
    assert "`aux_power_w` | " in md and "(fixed)" not in md.split("`aux_power_w` | ")[1].split("\n")[0]


@pytest.mark.parametrize("args, said", [
    (["--fix", "aux_power=300"], "--fix aux_power=300: cannot fix 'aux_power': not among traction_efficiency, "
                                 "recuperation_efficiency, aux_power_w, recuperation_limit_w"),
    (["--fix", "traction_efficiency=1.2"], "--fix traction_efficiency=1.2: traction_efficiency = '1.2': an "
                                           "efficiency lies in (0, 1]"),
    (["--fix", "recuperation_efficiency=0"], "an efficiency lies in (0, 1]"),
    (["--fix", "aux_power_w=-5"], "--fix aux_power_w=-5: aux_power_w = '-5': a power or gain is ≥ 0"),
    (["--fix", "aux_power_w=nan"], "--fix aux_power_w=nan: aux_power_w = 'nan': give a finite number"),
    (["--fix", "aux_power_w=abc"], "give a finite number"),
    (["--fix", "recuperation_limit_w=0"], "a recuperation limit is a braking power > 0 W"),
    (["--fix", "aux_power_w"], "--fix aux_power_w: give NAME=VALUE, e.g. aux_power_w=300"),
    (["--fix", "aux_power_w=300", "--fix", "aux_power_w=400"],
     "--fix aux_power_w=400: aux_power_w is already fixed (--fix aux_power_w=300)"),
    (["--fix", "loads.heater_w=1"], "cannot fix 'loads.heater_w'"),  # no --load heater_w
    (["--fix", "hvac.heating_w_per_k=50"], "cannot fix 'hvac.heating_w_per_k'"),  # no --hvac
    (["--efficiency", "power", "--fix", "traction_efficiency=0.9"],
     "--fix traction_efficiency=0.9: --efficiency power fits the efficiencies as tables"),
    (["--target", "fuel", "--fix", "aux_power_w=300"],
     "--fix aux_power_w=300: the fuel chain's fit holds no parameter at a given value"),
    (["--target", "wheel", "--fix", "aux_power_w=300"], "--fix aux_power_w=300: goes with --target battery"),
])
def test_bad_fix_is_refused_in_one_line(fix_log, args, said, tmp_path, capsys):
    log, eq = fix_log
    out = tmp_path / "x.toml"
    target = [] if "--target" in args else ["--target", "battery"]
    road = [] if "wheel" in args else ["--equation", str(eq)]
    rc = cli_main(["calibrate", str(log), *target, *road, "--out", str(out), *args])
    err = capsys.readouterr().err
    assert rc == 2 and said in err and "Traceback" not in err and not out.exists()
    assert len(err.strip().splitlines()) == 1, err


def test_fixable_names_are_in_the_help(capsys):
    with pytest.raises(SystemExit):
        cli_main(["calibrate", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    for name in ("--fix NAME=VALUE", "traction_efficiency", "aux_power_w", "recuperation_limit_w", "loads.COLUMN",
                 "hvac.heating_w_per_k"):
        assert name in text
