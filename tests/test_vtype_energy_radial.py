"""The ``radial`` factor (m·v·|ω|, the centripetal force in curves) and SUMO's radial drag:
by hand, and booked by ``vtype_energy`` beside SUMO 1.28's own emission output on a curved
road, live and replayed from FCD, at two step lengths (SUMO books the drag per step)."""

from __future__ import annotations

import math
import subprocess

import numpy as np
import pandas as pd
import pytest
import sumolib
from hypothesis import given
from hypothesis import strategies as st

from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.model.energy_params import energy_params_equation
from sumo_drvpw.model.terms import Inputs, parse_term, term_matrix
from sumo_drvpw.sim import run_scenario
from sumo_drvpw.sim.export import energy_model_params
from sumo_drvpw.sim.reader import yaw_rate
from sumo_probe import build_net, emitted_wh


def _inputs(v, yaw=None, m=1500.0):
    v = np.asarray(v, float)
    z = np.zeros_like(v)
    sig = {} if yaw is None else {"yaw_rate_rps": np.asarray(yaw, float)}
    return Inputs(v, z, z, z, z + m, z + 1.2041, sig)


def test_radial_factor_by_hand():
    """radial = m·v·|ω| [N] (either turning direction), radial*v1 = m·v²·|ω| [W]; 0 where
    the yaw rate is unknown (no signal, or NaN); booked under roll; its column is read."""
    x = _inputs([10.0, 20.0, 5.0], [0.1, -0.2, np.nan])
    got = term_matrix(["radial", "radial*v1"], x)
    np.testing.assert_allclose(got[:, 0], [1500 * 10 * 0.1, 1500 * 20 * 0.2, 0.0])
    np.testing.assert_allclose(got[:, 1], [1500 * 100 * 0.1, 1500 * 400 * 0.2, 0.0])
    np.testing.assert_array_equal(term_matrix(["radial"], _inputs([10.0, 3.0]))[:, 0], [0.0, 0.0])
    assert parse_term("radial").category == "roll" and parse_term("radial*v1").columns == ("yaw_rate_rps",)


def test_yaw_rate_takes_the_short_way_round():
    """The angle change over Δt, through north either way (359° → 1° is +2°, 10° → 350°
    is −20°), 0 without a last angle."""
    w = yaw_rate(np.array([359.0, np.nan, 10.0, 90.0]), np.array([1.0, 5.0, 350.0, 90.0]), 0.5)
    np.testing.assert_allclose(w, [math.radians(2.0) / 0.5, 0.0, math.radians(-20.0) / 0.5, 0.0],
                               atol=1e-12)


@given(st.floats(0.0, 360.0, exclude_max=True), st.floats(-179.9, 179.9), st.sampled_from([0.1, 0.5, 1.0]))
def test_yaw_rate_is_the_turn_whatever_the_heading(prev, turn, dt):
    """Property: a turn of d degrees in a step reads as radians(d)/Δt from any heading, SUMO's
    angle written in [0, 360) (through north either way)."""
    now = (prev + turn) % 360.0
    w = yaw_rate(np.array([prev]), np.array([now]), dt)[0]
    assert w == pytest.approx(math.radians(turn) / dt, abs=1e-9)


def test_sumos_radial_drag_is_a_term_at_c_over_the_step():
    """radialDragCoefficient c books as the term radial at c/Δt (SUMO's energy per step c·F);
    without a step length it is not booked and a note says so; export-vtype lists an
    equation's radial coefficient as c·Δt for SUMO, not as a term it has no place for."""
    p = {"radialDragCoefficient": 0.5, "airDragCoefficient": 0.3}
    eq, notes = energy_params_equation("x", p, 1500.0, "f: vType 'x'", step_s=0.25)
    assert eq.terms["radial"] == pytest.approx(2.0)
    eq0, notes0 = energy_params_equation("x", p, 1500.0, "f: vType 'x'")
    assert "radial" not in eq0.terms and any("not booked" in n for n in notes0)
    params, missing = energy_model_params(eq)
    assert params["radialDragCoefficient"] == 0.0
    assert any(m.startswith("radial coefficient 2 m/s") for m in missing)


ROUTES = """<routes>
  <vType id="ecar" vClass="passenger" mass="1600" emissionClass="Energy/unknown" sigma="0.5">
    <param key="airDragCoefficient" value="0.28"/>
    <param key="radialDragCoefficient" value="{c}"/>
  </vType>
  <vType id="edef" vClass="passenger" emissionClass="Energy/unknown" sigma="0.5">
    <param key="frontSurfaceArea" value="2.2"/>
  </vType>
  <route id="r" edges="e"/>
  <flow id="c" type="ecar" route="r" begin="0" end="40" period="6" departSpeed="0" departLane="best"/>
  <flow id="d" type="edef" route="r" begin="3" end="40" period="6" departSpeed="0" departLane="best"/>
</routes>"""


def _curve(d):
    """A 2-lane road: 200 m straight, a half circle of 40 m radius, 200 m straight."""
    pts = [(0.0, 0.0), (200.0, 0.0)] + [
        (200 + 40 * math.cos(-math.pi / 2 + k * math.pi / 24), 40 + 40 * math.sin(-math.pi / 2 + k * math.pi / 24))
        for k in range(1, 25)] + [(0.0, 80.0)]
    shape = " ".join(f"{x:.3f},{y:.3f}" for x, y in pts)
    build_net(d, '<nodes><node id="a" x="0" y="0"/><node id="b" x="0" y="80"/></nodes>',
              f'<edges><edge id="e" from="a" to="b" numLanes="2" speed="16" shape="{shape}"/></edges>',
              "--no-turnarounds")


def _emitted_wh(path, dt):
    """SUMO's emission output: electricity [Wh/s] × Δt summed per vehicle [Wh] (none nan)."""
    wh, nan = emitted_wh(path, dt)
    assert not nan
    return wh


@pytest.mark.parametrize("dt", [1.0, 0.25])
def test_vtype_energy_books_sumos_radial_drag(tmp_path, dt):
    """On a road with a half circle of 40 m radius, ``vtype_energy`` books each car as SUMO's
    emission output does, step by step, its radial drag included: per vehicle within 0.05 %
    (measured 2026-11-27: 0.99997–1.0001; SUMO writes 6 decimals). The drag is large there
    and grows as the step shortens, as SUMO books it: SUMO's own energy with the e-car's
    radialDragCoefficient 0.5 against 0 is +11 % at 1-s steps and +44 % at 0.25 s (measured;
    asserted > 5 % and growing), so the agreement fails without the term. An FCD replay of
    the run (angles from the FCD) books the same to 1e-3; one without angles books no drag
    and warns."""
    _curve(tmp_path)
    for c in ("0.5", "0"):
        (tmp_path / f"r{c}.rou.xml").write_text(ROUTES.format(c=c), encoding="utf-8")
    (tmp_path / "s.toml").write_text(
        f'equations = ["vtype_energy"]\n[sumo]\nnet = "n.net.xml"\nroutes = ["r0.5.rou.xml"]\nend = 150\n'
        f'step_length = {dt}\noptions = ["--no-warnings", "true", "--precision", "6", "--emission-output", '
        f'"{tmp_path / "em.xml"}", "--fcd-output", "{tmp_path / "fcd.xml"}"]\n[outputs]\nfigures = false\n', encoding="utf-8")
    res = run_scenario(tmp_path / "s.toml", tmp_path / "o")
    sumo = _emitted_wh(tmp_path / "em.xml", dt)
    cv = pd.read_csv(tmp_path / "o" / "chain_vehicles.csv")
    assert set(cv.equation) == {"vtype_energy.ecar", "vtype_energy.edef"} and len(cv) == 14
    np.testing.assert_allclose(cv.net_kwh * 1000.0, cv.key.map(sumo), rtol=5e-4)
    booked = res["assumptions"]["vtype_energy"]["booked"]
    assert f"c/Δt = {0.5 / dt:g} for Δt = {dt:g} s" in booked["ecar"]["radial_drag"]
    assert any("radial drag in curves of ecar, edef booked per step" in w for w in res["warnings"])
    # SUMO's own drag: the same cars with the coefficient 0
    subprocess.run([sumolib.checkBinary("sumo"), "-n", "n.net.xml", "-r", "r0.rou.xml", "-e", "150",
                    "--step-length", str(dt), "--emission-output", "em0.xml", "--precision", "6",
                    "--no-step-log", "--no-warnings"], check=True, capture_output=True, cwd=tmp_path)
    none = _emitted_wh(tmp_path / "em0.xml", dt)
    cars = [v for v in sumo if v.startswith("c.")]
    share = sum(sumo[v] for v in cars) / sum(none[v] for v in cars) - 1.0
    assert share > (0.05 if dt == 1.0 else 0.3)
    # replayed from the run's FCD: the angles there give the same drag
    assert cli_main(["fcd", str(tmp_path / "fcd.xml"), "--net", str(tmp_path / "n.net.xml"), "--vtypes",
                     str(tmp_path / "r0.5.rou.xml"), "--equation", "vtype_energy", "--end", "150",
                     "--out", str(tmp_path / "fcd"), "--no-figures"]) == 0
    a = cv.groupby("equation").net_kwh.sum()
    b = pd.read_csv(tmp_path / "fcd" / "chain_vehicles.csv").groupby("equation").net_kwh.sum()
    np.testing.assert_allclose(b.loc[a.index].values, a.values, rtol=1e-3)
    if dt == 1.0:  # an FCD written without angles: no drag, and a warning says so
        import json
        import re

        text = (tmp_path / "fcd.xml").read_text(encoding="utf-8")
        (tmp_path / "fcd_na.xml").write_text(re.sub(r' angle="[^"]*"', "", text), encoding="utf-8")
        assert cli_main(["fcd", str(tmp_path / "fcd_na.xml"), "--net", str(tmp_path / "n.net.xml"), "--vtypes",
                         str(tmp_path / "r0.5.rou.xml"), "--equation", "vtype_energy", "--end", "150",
                         "--out", str(tmp_path / "na"), "--no-figures"]) == 0
        warn = json.loads((tmp_path / "na" / "summary.json").read_text(encoding="utf-8"))["warnings"]
        assert any("has no angle column" in w and "booked as 0" in w for w in warn)
        c = pd.read_csv(tmp_path / "na" / "chain_vehicles.csv").groupby("equation").net_kwh.sum()
        assert c["vtype_energy.ecar"] < a["vtype_energy.ecar"] * 0.97


def _curvy_log(path, mu=0.02, seed=0, deg=False, gentle=False):
    """A 10-Hz log of 40 min: speed 5–25 m/s, curves of 80–400 m radius (``gentle``: 400–800 m) either way
    between straights, and the driving power of a 1500-kg car with a cornering drag
    μ·m·v²·|ω| planted (μ = ``mu``), plus noise of 150 W."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 2400.0, 0.1)
    v = 15.0 + 8.0 * np.sin(2 * np.pi * t / 300.0) + 2.0 * np.sin(2 * np.pi * t / 47.0)
    a = 8.0 * 2 * np.pi / 300.0 * np.cos(2 * np.pi * t / 300.0) + 2.0 * 2 * np.pi / 47.0 * np.cos(2 * np.pi * t / 47.0)
    seg = (t // 20.0).astype(int)  # 20-s pieces: a straight or a curve of one radius
    r = rng.choice([np.inf, 80.0, 150.0, 400.0] if not gentle else [np.inf, 400.0, 800.0], size=seg.max() + 1)
    sign = rng.choice([-1.0, 1.0], size=seg.max() + 1)
    yaw = sign[seg] * v / r[seg]  # at most 25²/80 = 7.8 m/s² of lateral acceleration
    m = 1500.0
    p = 1.05 * m * v * a + 0.32 * v ** 3 + 0.011 * m * 9.81 * v + mu * m * v ** 2 * np.abs(yaw)
    df = pd.DataFrame({"time_s": t, "speed_mps": v, "power_w": p + rng.normal(0.0, 150.0, len(t)),
                       "mass_kg": m, "yaw_rate_rps": np.degrees(yaw) if deg else yaw})
    df.to_csv(path, index=False)
    return df


def test_a_planted_cornering_drag_is_calibrated_from_a_logs_yaw_rate(tmp_path):
    """A log's ``yaw_rate_rps`` column feeds the radial factor: stepwise calibration with the
    candidate ``radial*v1`` recovers a planted cornering drag μ = 0.02 (the share of the
    centripetal force that acts as drag) within 5 %, and the other coefficients with it, and
    finds none (|μ| < 0.002) where none is planted; a
    yaw rate written in deg/s is refused, naming the column, the row and the unit."""
    from sumo_drvpw.data.measured import load_measured
    from sumo_drvpw.errors import UserError
    from sumo_drvpw.fit.calibrate import calibrate
    from sumo_drvpw.fit.physical import physical_reading

    _curvy_log(tmp_path / "log.csv")
    m = load_measured([tmp_path / "log.csv"])
    res = calibrate(m.inputs, m.power_w, ("acc", "aero", "roll", "radial*v1"), mask=m.usable)
    assert "radial*v1" in res.terms
    assert res.params["radial*v1"] == pytest.approx(0.02, rel=0.05)
    assert res.params["aero"] == pytest.approx(0.32, rel=0.02)
    assert res.params["acc"] == pytest.approx(1.05, rel=0.02)
    reading = physical_reading(res.params)["radial*v1"]
    assert reading["plausible"] and "slip angle" in reading["reads_as"]
    assert physical_reading({"radial*v1": -0.01})["radial*v1"]["plausible"] is False
    _curvy_log(tmp_path / "none.csv", mu=0.0, seed=1)  # nothing planted: nothing found
    m0 = load_measured([tmp_path / "none.csv"])
    r0 = calibrate(m0.inputs, m0.power_w, ("acc", "aero", "roll", "radial*v1"), mask=m0.usable)
    assert abs(r0.params.get("radial*v1", 0.0)) < 0.002
    _curvy_log(tmp_path / "deg.csv", deg=True)
    with pytest.raises(UserError, match=r"column 'yaw_rate_rps' is .* at row \d+, outside \[-10, 10\] rad/s"):
        load_measured([tmp_path / "deg.csv"])
    # gentle curves in deg/s stay within ±10 (at most 3.6 °/s), but no tyre carries 57× their grip
    _curvy_log(tmp_path / "gentle.csv", deg=True, gentle=True)
    with pytest.raises(UserError, match=r"column 'yaw_rate_rps' gives a lateral acceleration .* at row \d+, "
                                        r"above 12 m/s².*in deg/s\?"):
        load_measured([tmp_path / "gentle.csv"])
    _curvy_log(tmp_path / "gentle_rad.csv", gentle=True)
    assert load_measured([tmp_path / "gentle_rad.csv"]).usable.any()


def _curvy_trips(mu, n_trips=12, n=1500, seed=3, yaw=True):
    """Synthetic trips (0.5-s samples) through curves of 80–400 m radius either way, no
    temperature logged; truth 1.1·m·v·a + m·g·v·sin θ + 0.35·v³ + 0.012·m·g·v·cos θ +
    μ·m·v²·|ω|, noise 300 W."""
    from sumo_drvpw.model.constants import G

    rng = np.random.default_rng(seed)
    parts = []
    for i in range(n_trips):
        t = np.arange(n) * 0.5
        v = np.clip(12 + 6 * np.sin(t / 45.0 + i) + np.cumsum(rng.normal(0, 0.05, n)), 1.0, 30.0)
        seg = (t // (10.0 + i)).astype(int)
        r = rng.choice([np.inf, np.inf, 80.0, 150.0, 400.0], size=seg.max() + 1)  # ≤ 30²/80 m/s²
        w = rng.choice([-1.0, 1.0], size=seg.max() + 1)[seg] * v / r[seg]
        th = 0.02 * np.sin(t / (60.0 + 7 * i) + i)
        parts.append((v, np.gradient(v, 0.5), th, w, np.full(n, f"T{i:02d}")))
    v, a, th, w, trip = (np.concatenate(z) for z in zip(*parts))
    m = np.full(v.size, 1500.0)
    x = Inputs(v, a, th, np.zeros(v.size), m, np.full(v.size, 1.2),
               {"yaw_rate_rps": w} if yaw else {}, trip)
    p = (1.1 * m * v * a + m * G * v * np.sin(th) + 0.35 * v ** 3 + 0.012 * m * G * v * np.cos(th)
         + mu * m * v ** 2 * np.abs(w) + rng.normal(0, 300.0, v.size))
    return x, p, np.ones(v.size, bool), np.full(v.size, 0.5), trip


def test_the_closed_loop_keeps_a_planted_cornering_drag_on_whole_trips():
    """fit.physical.select_physical (the closed loop's physical candidates, trip-grouped
    cross-validation of per-trip traction energy): a planted cornering drag μ = 0.03 is kept
    with its reading within 10 %; none planted, none kept; without a yaw rate in the data
    (or a temperature, for c_r(T)) the candidate is not tried."""
    from sumo_drvpw.fit.physical import select_physical

    base = ["acc", "aero", "roll", "grade"]
    sel = select_physical(*_curvy_trips(0.03), base, candidates=("cornering drag", "c_r(T)"))
    assert sel["chosen"] == ["cornering drag"]
    step = next(s for s in sel["steps"] if s["accepted"])
    assert step["reading"]["value"] == pytest.approx(0.03, rel=0.1) and step["reading"]["plausible"]
    assert all(s["candidate"] != "c_r(T)" for s in sel["steps"])   # no temperature: not tried
    assert select_physical(*_curvy_trips(0.0, seed=4), base, candidates=("cornering drag",))["chosen"] == []
    none = select_physical(*_curvy_trips(0.03, yaw=False), base, candidates=("cornering drag",))
    assert none["chosen"] == [] and none["steps"] == []


def test_a_replay_of_fcd_written_every_other_step_books_sumos_radial_drag(tmp_path):
    """An FCD written every 2 steps (device.fcd.period 2 at 1-s steps, its header says so):
    SUMO booked its radial drag per 1-s step, c·m·v·|Δψ|/Δt for each, so the replay books
    the rows' angle change at c/Δt of the recording's step (1 s), not of the rows' interval
    (2 s, which booked half: 0.50 of SUMO's, measured 2026-11-27). The drag alone: the same
    cars with the e-car's radialDragCoefficient 0.5 and 0, in SUMO's emission output and in
    the replay (within 5 %: the rows' speed stands for both steps'). On Dask the summary
    names the same step, and an FCD without angles warns as locally."""
    _curve(tmp_path)
    for c in ("0.5", "0"):
        (tmp_path / f"r{c}.rou.xml").write_text(ROUTES.format(c=c), encoding="utf-8")
        subprocess.run([sumolib.checkBinary("sumo"), "-n", "n.net.xml", "-r", f"r{c}.rou.xml", "-e", "150",
                        "--emission-output", f"em{c}.xml", "--precision", "6", "--fcd-output", f"fcd{c}.xml",
                        "--device.fcd.period", "2", "--no-step-log", "--no-warnings"],
                       check=True, capture_output=True, cwd=tmp_path)
    sumo = {c: _emitted_wh(tmp_path / f"em{c}.xml", 1.0) for c in ("0.5", "0")}
    ours = {}
    for c in ("0.5", "0"):
        assert cli_main(["fcd", str(tmp_path / "fcd0.5.xml"), "--net", str(tmp_path / "n.net.xml"), "--vtypes",
                         str(tmp_path / f"r{c}.rou.xml"), "--equation", "vtype_energy", "--out",
                         str(tmp_path / f"o{c}"), "--no-figures"]) == 0
        cv = pd.read_csv(tmp_path / f"o{c}" / "chain_vehicles.csv")
        ours[c] = dict(zip(cv.key, cv.net_kwh * 1000.0))
    cars = [v for v in ours["0"] if v.startswith("c.")]
    drag_sumo = sum(sumo["0.5"][v] - sumo["0"][v] for v in cars)
    drag_ours = sum(ours["0.5"][v] - ours["0"][v] for v in cars)
    assert drag_sumo > 10.0  # Wh: a drag to book
    assert drag_ours / drag_sumo == pytest.approx(1.0, abs=0.05)  # measured 1.007
    import json
    import re

    note = "the term radial at c/Δt = 0.5 for Δt = 1 s"
    summary = json.loads((tmp_path / "o0.5" / "summary.json").read_text(encoding="utf-8"))
    assert note in summary["assumptions"]["vtype_energy"]["booked"]["ecar"]["radial_drag"]
    # on Dask (vehicle buckets) the summary says the same; an FCD without angles warns there too
    from sumo_drvpw.sim.fcd_dask import process_fcd_dask

    (tmp_path / "na.xml").write_text(re.sub(r' angle="[^"]*"', "", (tmp_path / "fcd0.5.xml").read_text(encoding="utf-8")), encoding="utf-8")
    dk = process_fcd_dask(tmp_path / "na.xml", tmp_path / "dask", net=tmp_path / "n.net.xml",
                          equations=["vtype_energy"], vtype_files=[tmp_path / "r0.5.rou.xml"], buckets=2, workers=1)
    assert note in dk["assumptions"]["vtype_energy"]["booked"]["ecar"]["radial_drag"]
    assert any("has no angle column" in w and "booked as 0" in w for w in dk["warnings"])
