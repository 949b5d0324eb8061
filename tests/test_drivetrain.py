"""The grade at the wheels (sumo_drvpw.fit.drivetrain): a motor-side grade coefficient read
through the η that inertia by direction or the recuperation scale show."""

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from sumo_drvpw.fit.drivetrain import ETA_INERTIA_MIN, WHEEL_GRADE_BAND, drivetrain_eta, wheel_grade
from sumo_drvpw.fit.physical import physical_reading, regime_fit
from sumo_drvpw.model.constants import G
from sumo_drvpw.model.terms import Inputs, term_matrix


def _drive(seed=1, n_trips=8, n=3000):
    rng = np.random.default_rng(seed)
    parts = []
    for i in range(n_trips):
        amp, per = 2.0 + 9.0 * (i % 4) / 3.0, 40.0 + 25.0 * (i % 3)
        v = np.clip(14 + amp * np.sin(np.arange(n) / per + i) + np.cumsum(rng.normal(0, 0.1, n)), 0.5, 33)
        th = 0.03 * np.sin(np.arange(n) / (80.0 + 10 * i) + i)
        parts.append((v, np.gradient(v, 0.5), th))
    v, a, th = (np.concatenate(z) for z in zip(*parts))
    m = np.full(v.size, 1500.0)
    x = Inputs(v, a, th, np.zeros(v.size), m, np.full(v.size, 1.2))
    # the wheel power: mass factor 1.06, grade exactly 1, drag and rolling
    pw = 1.06 * m * v * a + m * G * v * np.sin(th) + 0.35 * v ** 3 + 0.012 * m * G * v * np.cos(th)
    return x, pw, rng


def test_hand_values_of_the_i3_deliverable():
    # docs/closing-the-loop.md, i3_all_trips: acc 1.049, acc_pos 0.2436, grade 1.135
    w = wheel_grade({"acc": 1.049, "acc_pos": 0.2436, "grade": 1.135, "aero": 0.31})
    eta = 1.0 / math.sqrt((1.049 + 0.2436) / 1.049)
    assert w["eta"] == pytest.approx(eta, rel=1e-12) and eta == pytest.approx(0.9009, abs=1e-4)
    assert w["value"] == pytest.approx(1.135 * eta, rel=1e-12) and w["plausible"]
    # the recuperation scale 1 + r = η², where there is no acc_pos
    assert drivetrain_eta({"acc": 1.1, "grade": 1.1}, 0.81)[0] == pytest.approx(0.9, rel=1e-12)
    assert wheel_grade({"acc": 1.1, "grade": 1.1}, 0.81)["value"] == pytest.approx(0.99, rel=1e-12)


def test_no_reading_without_an_eta_or_a_grade():
    assert wheel_grade({"acc": 1.1, "grade": 1.1, "roll": 0.01}) is None
    assert wheel_grade({"acc": 1.1, "acc_pos": 0.2, "roll": 0.01}) is None
    assert drivetrain_eta({"acc": 1.1, "acc_pos": -1.2}) is None          # ratio < 0: no η
    assert drivetrain_eta({"acc": 1.1}, regime_scale=0.0) is None
    assert "at_wheels" not in physical_reading({"acc": 1.1, "grade": 1.1})["grade"]


@pytest.mark.parametrize("eta", [0.85, 0.9, 0.95])
def test_planted_symmetric_drivetrain_reads_grade_one_at_the_wheels(eta):
    """Motor-side power = wheel power / η driving, × η recuperating. The free grade reads
    above 1 (about 1/η), the inertia candidate's η too high (it absorbs the other terms'
    asymmetry), the product 1 within 1 %; with the recuperation scale (the exact model)
    within 0.5 %."""
    x, pw, rng = _drive()
    pm = np.where(pw > 0, pw / eta, pw * eta) + rng.normal(0, 400, pw.size)
    terms = ["acc", "acc_pos", "grade", "aero", "roll"]
    b = dict(zip(terms, np.linalg.lstsq(term_matrix(terms, x), pm, rcond=None)[0]))
    assert b["grade"] > 1.02
    w = wheel_grade(b)
    assert w["value"] == pytest.approx(1.0, abs=0.01) and w["plausible"]
    assert eta < w["eta"] < 1.0
    assert physical_reading(b)["grade"]["at_wheels"]["value"] == w["value"]
    base = ["acc", "grade", "aero", "roll"]
    br, r = regime_fit(term_matrix(base, x), pm, True)
    wr = wheel_grade(dict(zip(base, br)), 1.0 + r)
    assert wr["eta"] == pytest.approx(eta, abs=0.01)
    assert wr["value"] == pytest.approx(1.0, abs=0.005)


def test_asymmetric_inertia_with_an_exact_grade_is_flagged():
    """Inertial power at 1.1/0.75 speeding up and 1.1 slowing down, everything else (grade 1)
    symmetric: an asymmetry that is no drivetrain. η from the inertia ≈ √0.75 = 0.87, the
    grade ≈ 1, so the grade at the wheels reads 0.87: below the band, flagged."""
    x, pw, rng = _drive(seed=2)
    m, v, a = x.mass, x.v, x.a
    pm = pw + np.where(a > 0, 1.1 / 0.75 - 1.06, 0.04) * m * v * a + rng.normal(0, 400, pw.size)
    terms = ["acc", "acc_pos", "grade", "aero", "roll"]
    b = dict(zip(terms, np.linalg.lstsq(term_matrix(terms, x), pm, rcond=None)[0]))
    assert b["grade"] == pytest.approx(1.0, abs=0.02)
    w = wheel_grade(b)
    assert w["value"] < WHEEL_GRADE_BAND[0] and not w["plausible"] and "disagree" in w["note"]


@settings(max_examples=200, deadline=None)
@given(eta=st.floats(0.6, 1.2), f=st.floats(1.0, 1.3), k=st.floats(0.7, 1.4))
def test_exact_drivetrain_coefficients_read_back(eta, f, k):
    """Coefficients of a drivetrain η each way, rotating-mass factor f and mass ratio k
    (traction acc k·f/η, recuperation acc k·f·η, grade k/η) read back η and k exactly —
    where η is a drivetrain's (ETA_INERTIA_MIN … 1); else no grade at the wheels."""
    terms = {"acc": k * f * eta, "acc_pos": k * f * (1.0 / eta - eta), "grade": k / eta}
    w = wheel_grade(terms)
    assert drivetrain_eta(terms)[0] == pytest.approx(eta, rel=1e-9)
    if not ETA_INERTIA_MIN <= drivetrain_eta(terms)[0] <= 1.0:
        assert w is None
        return
    assert w["eta"] == pytest.approx(eta, rel=1e-9)
    assert w["value"] == pytest.approx(k, rel=1e-9)
    assert w["plausible"] == (WHEEL_GRADE_BAND[0] <= w["value"] <= WHEEL_GRADE_BAND[1])


@pytest.mark.parametrize("engine", ["local", "memory"])
def test_calibrate_says_the_grade_at_the_wheels(tmp_path, capsys, engine):
    """`sumo-drvpw calibrate` on a motor-side log of a planted symmetric drivetrain (η 0.9)
    with acc_pos among the candidates prints the grade at the wheels (≈ 1) and writes it into
    the equation's physical reading, streamed and in memory alike."""
    import pandas as pd

    from sumo_drvpw.cli import main
    from sumo_drvpw.model.equations import load_equation

    x, pw, rng = _drive(n_trips=4)
    pm = np.where(pw > 0, pw / 0.9, pw * 0.9) + rng.normal(0, 400, pw.size)
    pd.DataFrame({"time_s": np.arange(pw.size) * 0.5, "speed_mps": x.v, "accel_mps2": x.a,
                  "grade_rad": x.theta, "mass_kg": x.mass, "power_w": pm}).to_parquet(tmp_path / "log.parquet")
    (tmp_path / "c.toml").write_text('terms = ["acc", "acc_pos", "grade", "aero", "roll"]\n', encoding="utf-8")
    out = tmp_path / "eq.toml"
    assert main(["calibrate", str(tmp_path / "log.parquet"), "--candidates", str(tmp_path / "c.toml"),
                 "--out", str(out), "--engine", engine]) == 0
    printed = capsys.readouterr().out
    eq = load_equation(out)
    w = wheel_grade(eq.terms)
    assert w["value"] == pytest.approx(1.0, abs=0.01)
    assert f"grade at the wheels c_grade·η = {w['value']:.3f}" in printed and "warning: grade" not in printed
    assert eq.provenance["physical"]["reading"]["grade"]["at_wheels"]["value"] == pytest.approx(w["value"], rel=1e-9)


def test_calibrate_says_when_the_constraints_held_the_grade(tmp_path, capsys):
    """The grade logged 2.5 × too steep reads 0.4 free (implausible): the candidate file's
    constraint holds it at 1, and the grade at the wheels is printed as what it then is, a
    reading of η alone — no warning."""
    import pandas as pd

    from sumo_drvpw.cli import main

    x, pw, rng = _drive(n_trips=4)
    pm = np.where(pw > 0, pw / 0.9, pw * 0.9) + rng.normal(0, 400, pw.size)
    pd.DataFrame({"time_s": np.arange(pw.size) * 0.5, "speed_mps": x.v, "accel_mps2": x.a,
                  "grade_rad": 2.5 * x.theta, "mass_kg": x.mass, "power_w": pm}).to_parquet(tmp_path / "log.parquet")
    (tmp_path / "c.toml").write_text('terms = ["acc", "acc_pos", "grade", "aero", "roll"]\n'
                                     '[constraints]\ngrade = { fixed = 1.0 }\n', encoding="utf-8")
    assert main(["calibrate", str(tmp_path / "log.parquet"), "--candidates", str(tmp_path / "c.toml"),
                 "--out", str(tmp_path / "eq.toml")]) == 0
    printed = capsys.readouterr().out
    assert "physically constrained fit used" in printed
    assert "the grade is held at its constraint, so this reads only η" in printed
    assert "warning: grade" not in printed
