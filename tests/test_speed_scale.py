"""A speed that reads high or low, corrected in the data (issue #11 §3; data/corrections.py
scale_speed, model/measurement.py speed_scale): the logged speed times a declared scale, or
each trip's own scale against the GPS speed logged beside it, before acceleration, distance
and grade are derived from it; kept in the calibrated equation's [measurement] and never used
in SUMO. Planted: a speedometer 3 % high puts 1/k² into acc and 1/k³ into aero unless
corrected."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.data.log import ReadOptions, from_frame
from sumo_drvpw.data.measured import measure
from sumo_drvpw.errors import UserError
from sumo_drvpw.fit.calibrate import calibrate
from sumo_drvpw.model.constants import G
from sumo_drvpw.model.measurement import Measurement, measurement_from_dict

REPO = Path(__file__).resolve().parents[1]
#: the planted vehicle: mass [kg], mass factor, C_d·A [m²], c_r, air density [kg/m³]
MASS, ACC, CDA, CR, RHO = 1500.0, 1.0, 0.6, 0.012, 1.2
#: the speedometer reads this much of the true speed
HIGH = 1.03


def _trips(n_trips=3, n=1500, seed=0) -> pd.DataFrame:
    """Trips at 1 Hz on a hilly road: logged speed HIGH × the true speed, a GPS speed (the
    true speed, 0.3 % noise and a few dropouts to 0 and jumps), elevation over the true
    distance and the driving power of the planted vehicle at the true speed."""
    rng = np.random.default_rng(seed)
    out = []
    for j in range(n_trips):
        t = np.arange(n, dtype=float)
        ph = rng.uniform(0, 2 * np.pi, 3)
        v = 16.0 + 7.0 * np.sin(t / 40.0 + ph[0]) + 3.0 * np.sin(t / 11.0 + ph[1])
        a = 7.0 / 40.0 * np.cos(t / 40.0 + ph[0]) + 3.0 / 11.0 * np.cos(t / 11.0 + ph[1])
        s = np.cumsum(v)  # true distance [m]
        h = 30.0 * np.sin(s / 900.0 + ph[2])
        sin_th = np.sin(np.arctan(30.0 / 900.0 * np.cos(s / 900.0 + ph[2])))
        p = (ACC * MASS * v * a + MASS * G * v * sin_th + 0.5 * RHO * CDA * v ** 3
             + CR * MASS * G * v * np.sqrt(1 - sin_th ** 2))
        gps = v * (1 + rng.normal(0, 0.003, n))
        bad = rng.choice(n, 20, replace=False)
        gps[bad[:10]] = 0.0
        gps[bad[10:]] *= 1.4
        out.append(pd.DataFrame({"trip_id": f"t{j}", "time_s": t, "speed_mps": HIGH * v, "gps_speed_mps": gps,
                                 "elevation_m": h, "power_w": p, "mass_kg": MASS, "air_density_kgm3": RHO}))
    return pd.concat(out, ignore_index=True)


def _read(df, meas):
    return measure(from_frame(df, options=ReadOptions(measurement=meas)), None)


def test_a_speed_scale_measured_against_the_gps_speed_returns_the_vehicle(tmp_path):
    """Uncorrected, the fit reads acc 1/1.03² = 0.943 and C_d·A 1/1.03³ of the planted; the
    scale measured per trip against the GPS speed (dropouts and jumps in it) is 1/1.03 within
    0.1 %, and the fit on the corrected speed returns acc 1 and C_d·A 0.6 within 1 %; a
    declared 1/1.03 the same."""
    df = _trips()
    fits = {}
    for key, meas in (("none", None), ("gps", Measurement(speed_scale="gps")),
                      ("declared", Measurement(speed_scale=1 / HIGH))):
        m = _read(df, meas)
        res = calibrate(m.inputs, m.power_w, ("acc", "grade", "aero", "roll"), mask=m.usable,
                        p_enter=1.0, p_remove=1.0)
        fits[key] = (res.to_equation(key).terms, m.counts.get("speed_scale"))
    (raw, _), (gps, k), (decl, kd) = fits["none"], fits["gps"], fits["declared"]
    assert raw["acc"] == pytest.approx(ACC / HIGH ** 2, rel=0.01)
    assert 2 * raw["aero"] / RHO == pytest.approx(CDA / HIGH ** 3, rel=0.02)
    assert set(k) == {"t0", "t1", "t2"} and all(x == pytest.approx(1 / HIGH, rel=1e-3) for x in k.values())
    assert kd == {t: pytest.approx(1 / HIGH) for t in ("t0", "t1", "t2")}
    for terms in (gps, decl):
        assert terms["acc"] == pytest.approx(ACC, rel=0.01)
        assert 2 * terms["aero"] / RHO == pytest.approx(CDA, rel=0.01)
        assert terms["roll"] == pytest.approx(CR, rel=0.03)
        assert terms["grade"] == pytest.approx(1.0, rel=0.02)


def test_the_scale_reaches_acceleration_distance_and_grade_before_power():
    """k on the speed is k on the derived acceleration, exactly, and 1/k on the grade from
    elevation over the (scaled) distance, so the grade power m·g·v·sin θ, the elevation's rate,
    keeps its trip sum; the measured power is untouched. The GPS speed comparison then agrees."""
    df = _trips(n_trips=1)
    k = 0.95
    a, b = _read(df, None), _read(df, Measurement(speed_scale=k))
    np.testing.assert_allclose(b.inputs.v, k * a.inputs.v, rtol=1e-12)
    np.testing.assert_allclose(b.inputs.a, k * a.inputs.a, rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(b.power_w, a.power_w)
    mid = slice(200, -200)  # (the 100-m elevation window spans 5 % less distance at the ends)
    ratio = np.tan(b.inputs.theta[mid]) / np.tan(a.inputs.theta[mid])
    assert np.median(ratio) == pytest.approx(1 / k, rel=2e-3)
    rise = [float(np.sum(m.inputs.v * np.sin(m.inputs.theta))) for m in (a, b)]
    assert rise[1] == pytest.approx(rise[0], rel=0.01)
    gps = _read(df, Measurement(speed_scale="gps"))
    assert gps.counts["speed_gps_sum_mm"] / gps.counts["gps_speed_sum_mm"] == pytest.approx(1.0, abs=0.005)
    assert a.counts["speed_gps_sum_mm"] / a.counts["gps_speed_sum_mm"] == pytest.approx(HIGH, abs=0.005)


def test_the_measurement_table_keeps_it_and_refuses_what_is_no_scale():
    for v in ("gps", 0.984):
        m = measurement_from_dict({"speed_scale": v}, "e.toml")
        assert m.speed_scale == v and not m.identity
        assert measurement_from_dict(m.to_dict(), "e.toml") == m
        assert "speed" in m.describe()
    assert measurement_from_dict({"speed_scale": 1.0}, "e.toml").identity
    for bad, needle in ((1.5, "more than 20% from 1"), ("fast", "must be \"gps\" or a finite number"),
                        (True, "must be \"gps\" or a finite number"), (float("nan"), "finite")):
        with pytest.raises(UserError, match="e.toml \\[measurement\\] speed_scale") as e:
            measurement_from_dict({"speed_scale": bad}, "e.toml")
        assert needle in str(e.value) and "\n" not in str(e.value)


def test_a_gps_scale_without_its_gps_speed_is_refused_by_name():
    df = _trips(n_trips=2)
    with pytest.raises(UserError, match="needs a GPS speed logged beside the speed") as e:
        _read(df.drop(columns="gps_speed_mps"), Measurement(speed_scale="gps"))
    assert "gps_speed" in str(e.value)
    short = df.copy()
    short.loc[short["trip_id"] == "t1", "gps_speed_mps"] = np.where(
        np.arange(1500) < 60, short.loc[short["trip_id"] == "t1", "gps_speed_mps"], np.nan)
    with pytest.raises(UserError, match="trip 't1'.*at least 100 steady samples"):
        _read(short, Measurement(speed_scale="gps"))


def test_calibrate_keeps_it_and_compare_reads_new_logs_with_it(tmp_path, capsys):
    """calibrate --speed-scale gps writes speed_scale = "gps" into the equation's [measurement]
    and its acc is the vehicle's; compare with that equation re-applies it (says so, and the
    scale per trip); a scale 50 % off is refused in one line, nothing written."""
    from sumo_drvpw.cli import main as cli_main
    import tomllib

    f = tmp_path / "log.parquet"
    _trips().to_parquet(f)
    eq = tmp_path / "eq.toml"
    assert cli_main(["calibrate", str(f), "--speed-scale", "gps", "--candidates", "acc,grade,aero,roll",
                     "--out", str(eq)]) == 0
    out = capsys.readouterr().out
    assert "note: speed scaled by 0.97" in out
    doc = tomllib.loads(eq.read_text(encoding="utf-8"))
    assert doc["measurement"]["speed_scale"] == "gps"
    assert doc["terms"]["acc"] == pytest.approx(ACC, rel=0.01)
    assert cli_main(["compare", str(f), "--equation", str(eq), "--out", str(tmp_path / "c")]) == 0
    out = capsys.readouterr().out
    assert "speed scaled per trip to the GPS speed" in out and "note: speed scaled by 0.97" in out
    assert cli_main(["calibrate", str(f), "--speed-scale", "1.5", "--out", str(tmp_path / "x.toml")]) == 2
    err = capsys.readouterr().err
    assert "--speed-scale" in err and "20%" in err and not (tmp_path / "x.toml").exists()


@pytest.mark.sumo
def test_sumo_never_uses_it(tmp_path):
    """The same road load with and without a [measurement] speed scale (0.9, and "gps") books
    the same energy in a SUMO run, whose speeds are exact."""
    from sumo_drvpw.sim import run_scenario

    body = '[terms]\nacc = 1.0\ngrade = 1.0\naero = 0.35\nroll = 0.012\n'
    eqs = []
    for name, meas in (("plain", ""), ("scaled", "[measurement]\nspeed_scale = 0.9\n"),
                       ("gps", '[measurement]\nspeed_scale = "gps"\n')):
        p = tmp_path / f"{name}.toml"
        p.write_text(f'[equation]\nname = "{name}"\n{body}{meas}', encoding="utf-8")
        eqs.append(str(p))
    s = run_scenario(REPO / "scenarios" / "highway.toml", tmp_path / "o", end=60, equations=eqs, figures=False)
    e = {n: s["equations"][n]["energy_j"] for n in ("plain", "scaled", "gps")}
    assert e["plain"] and e["plain"] == e["scaled"] == e["gps"]


def _two_gps(df, factor, seed=1):
    """``df`` with a second GPS speed, gps_speed_phone_mps, ``factor`` × the first and its own
    0.3 % noise, put first among the columns."""
    rng = np.random.default_rng(seed)
    phone = df["gps_speed_mps"].to_numpy() * factor * (1 + rng.normal(0, 0.003, len(df)))
    return pd.concat([pd.DataFrame({"gps_speed_phone_mps": phone}), df], axis=1)


def test_two_gps_speeds_that_disagree_are_refused_until_one_is_named():
    """A phone's GPS speed 2 % above the logger's: 'gps' does not take the first column
    silently (it would scale the speed 2 % wrong), it refuses in one line naming both and how to
    name one; "gps:COLUMN" scales to that one. Two that agree scale as one does."""
    df = _two_gps(_trips(n_trips=2), 1.02)
    with pytest.raises(UserError) as e:
        _read(df, Measurement(speed_scale="gps"))
    msg = str(e.value)
    assert "gps_speed_phone_mps" in msg and "gps_speed_mps" in msg and "disagree" in msg and "\n" not in msg
    assert 'speed_scale = "gps:gps_speed_phone_mps" or "gps:gps_speed_mps"' in msg
    for col, k in (("gps_speed_mps", 1 / HIGH), ("gps_speed_phone_mps", 1.02 / HIGH)):
        m = _read(df, measurement_from_dict({"speed_scale": f"gps:{col}"}, "e.toml"))
        assert m.counts["speed_scale_column"] == col and m.counts["speed_gps_column"] == col
        assert all(x == pytest.approx(k, rel=1e-3) for x in m.counts["speed_scale"].values())
        # the speed now agrees with the GPS speed it was scaled to
        assert m.counts["speed_gps_sum_mm"] / m.counts["gps_speed_sum_mm"] == pytest.approx(1.0, abs=0.005)
    agree = _read(_two_gps(_trips(n_trips=2), 1.0), Measurement(speed_scale="gps"))
    assert all(x == pytest.approx(1 / HIGH, rel=1e-3) for x in agree.counts["speed_scale"].values())
    with pytest.raises(UserError, match="no column gps_speed_obd_mps .its GPS speeds: gps_speed_phone_mps, gps_"):
        _read(df, Measurement(speed_scale="gps:gps_speed_obd_mps"))


def test_a_named_gps_column_is_kept_in_the_table_and_checked():
    m = measurement_from_dict({"speed_scale": "gps:gps_speed_mps"}, "e.toml")
    assert m.speed_scale == "gps:gps_speed_mps" and measurement_from_dict(m.to_dict(), "e.toml") == m
    assert "gps_speed_mps" in m.describe()
    with pytest.raises(UserError, match="e.toml \\[measurement\\] speed_scale: 'gps:speed_mps' names no GPS speed"):
        measurement_from_dict({"speed_scale": "gps:speed_mps"}, "e.toml")


def test_compare_names_the_gps_column_on_the_command_line(tmp_path, capsys):
    """--speed-scale gps:COLUMN, in memory and streamed alike; plain gps refused in one line."""
    from sumo_drvpw.cli import main as cli_main

    f = tmp_path / "log.parquet"
    _two_gps(_trips(n_trips=2), 1.02).to_parquet(f)
    eq = tmp_path / "eq.toml"
    eq.write_text('[equation]\nname = "eq"\n[terms]\nacc = 1.0\ngrade = 1.0\naero = 0.36\nroll = 0.012\n',
                  encoding="utf-8")
    r2 = {}
    for engine in ("memory", "local"):
        out = tmp_path / engine
        assert cli_main(["compare", str(f), "--equation", str(eq), "--speed-scale", "gps:gps_speed_mps",
                         "--engine", engine, "--out", str(out)]) == 0
        doc = __import__("json").loads((out / "report.json").read_text(encoding="utf-8"))
        assert doc["context"]["counts"]["speed_scale_column"] == "gps_speed_mps"
        r2[engine] = doc["equations"]["eq"]["r2"]
    assert r2["local"] == pytest.approx(r2["memory"], rel=1e-9)
    capsys.readouterr()
    assert cli_main(["compare", str(f), "--equation", str(eq), "--speed-scale", "gps",
                     "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert "disagree" in err and len(err.splitlines()) == 1 and not (tmp_path / "x").exists()
    # named as the user types it on the command line (the library names the [measurement] setting)
    assert "--speed-scale gps:gps_speed_phone_mps or --speed-scale gps:gps_speed_mps" in err, err
