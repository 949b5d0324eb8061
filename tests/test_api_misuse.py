"""The Python API as a researcher's script uses it (a rehearsal found each of these): a
built-in scenario's name, clear UserErrors instead of tracebacks for inputs of different
lengths and options out of their meaning, a vehicle by its name, and a free fit that says
which coefficients read implausibly."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.data.log import ReadOptions, from_frame
from sumo_drvpw.data.measured import measure
from sumo_drvpw.errors import UserError
from sumo_drvpw.fit.calibrate import calibrate
from sumo_drvpw.model.terms import Inputs
from sumo_drvpw.model.vehicles import load_vehicle


def _planted(acc=1.05, n=4000, seed=0):
    rng = np.random.default_rng(seed)
    v, a, zero = rng.uniform(1, 30, n), rng.normal(0, 0.5, n), np.zeros(n)
    x = Inputs(v=v, a=a, theta=zero, wind=zero, mass=np.full(n, 1500.0), rho=np.full(n, 1.2041))
    return x, acc * 1500 * v * a + 0.35 * v ** 3 + 0.009 * 1500 * 9.81 * v + rng.normal(0, 200, n)


def test_a_free_fit_names_its_implausible_coefficients():
    """calibrate() returned acc 0.76 on the Prius Gen-2 logs without a word (the CLI refits
    it under constraints): the result now lists it and its summary says so."""
    x, y = _planted(acc=1.05)
    res = calibrate(x, y, ("acc", "aero", "roll"))
    assert res.implausible == {} and "implausible" not in res.summary()
    x, y = _planted(acc=0.7)
    res = calibrate(x, y, ("acc", "aero", "roll"))
    assert list(res.implausible) == ["acc"] and "lag" in res.implausible["acc"]
    assert "implausible as physics: acc" in res.summary()
    assert "implausible" not in res.summary(physics=False)


def test_inputs_of_different_lengths_are_one_user_error():
    x, y = _planted()
    with pytest.raises(UserError, match=r"inputs have 4000 samples, the measured power 3995"):
        calibrate(x, y[:-5], ("acc", "aero"))
    with pytest.raises(UserError, match=r"the mask 3995"):
        calibrate(x, y, ("acc", "aero"), mask=np.ones(3995, bool))
    with pytest.raises(UserError, match=r"measured power is 0 on all 4000 usable samples"):
        calibrate(x, np.zeros(4000), ("acc", "aero"))  # (was: zeros and a statsmodels RuntimeWarning)


def test_a_vehicle_by_name_options_and_targets_checked(tmp_path):
    df = pd.DataFrame({"time_s": np.arange(200) * 0.5, "speed_mps": np.linspace(0, 20, 200)})
    log = from_frame(df, "bmw_i3")  # a name, as --vehicle takes it (was: AttributeError)
    assert log.inputs().mass[0] == pytest.approx(load_vehicle("bmw_i3").mass_kg)
    assert from_frame(df, None, ReadOptions(grade_window_m=np.int64(100))) is not None
    for bad in ({"grade_window_m": -50.0}, {"accel_outlier_mps2": -1.0}, {"accel_window_s": float("nan")},
                {"grade_outlier": 0.0}, {"accel_noise_mps2": "x"}):
        with pytest.raises(UserError, match=f"reading option {next(iter(bad))}"):
            from_frame(df, "bmw_i3", ReadOptions(**bad))
    with pytest.raises(UserError, match="target must be one of"):
        measure(log, load_vehicle("bmw_i3"), target="bogus")


def test_a_chain_without_its_input_is_one_user_error(tmp_path):
    from sumo_drvpw.fit.chain import calibrate_on

    n = 400
    df = pd.DataFrame({"time_s": np.arange(n) * 0.5, "speed_mps": 10 + 5 * np.sin(np.arange(n) / 20),
                       "battery_voltage_v": 360.0, "battery_current_a": 20.0})
    veh = load_vehicle("bmw_i3")
    m = measure(from_frame(df, veh), veh, target="battery")
    with pytest.raises(UserError, match="give the chain's input"):
        calibrate_on(m)


@pytest.mark.sumo
def test_run_scenario_takes_a_builtin_scenarios_name():
    """`sumo-drvpw run city` worked, run_scenario("city") said 'scenario file not found'."""
    from sumo_drvpw.sim import run_scenario

    res = run_scenario("city", None, end=20, figures=False)
    assert res["steps"] == 40 and len(res.vehicles) > 0
    with pytest.raises(UserError, match="unknown built-in scenario 'nocity'"):
        run_scenario("nocity", None)


def test_a_traced_equations_measurement_finding_says_what_to_do_instead():
    """diagnose's traced equation keeps `[grade_accelerometer]` (the logs' grade measured
    wrongly); on a held-out log, in compare and in SUMO it failed with 'needs the signal
    grade_accelerometer, which the data do not have' — though the log had its accelerometer.
    It now says it is a measurement-side finding, corrected in the data: recalibrate on logs
    read with the correction. An ordinary log-only term keeps its message."""
    from sumo_drvpw.model.equations import Equation
    from sumo_drvpw.sim.scenario import load_scenario
    from sumo_drvpw.sim.scenario_paths import scenario_path

    eq = Equation("traced", {"acc": 1.0, "grade": 1.0, "[grade_accelerometer]": 1.15})
    x, _ = _planted(n=10)
    with pytest.raises(UserError, match=r"measurement-side finding of diagnose \(the grade measured by the "
                                        r"accelerometer.*recalibrate the equation on the logs read with"):
        eq.power(x)
    with pytest.raises(UserError, match=r"cannot run in SUMO: term '\[grade_accelerometer\]' is a measurement-side"):
        load_scenario(scenario_path("city"), equations=[eq])
    with pytest.raises(UserError, match=r"term '\[ambient_c\]\*v1' needs the log-only signal 'ambient_c'"):
        load_scenario(scenario_path("city"), equations=[Equation("t", {"acc": 1.0, "[ambient_c]*v1": -5.0})])


def test_python_api_outputs_are_whole_sets_as_the_commands_are(tmp_path):
    """run_scenario(out_dir=D) and RunResult.write(D) into a folder an earlier run wrote left
    that run's files beside the new ones (its chain CSVs beside a summary without a chain),
    and wrote into a folder of the user's without a word (a rehearsal, 2026-11-29): now an
    earlier set's files go, a manifest.json lists the set, and a folder or file of the
    user's is refused unless force=True, which keeps it (and leaves it out of the manifest)."""
    import json

    from sumo_drvpw.errors import OutputExists
    from sumo_drvpw.sim import run_scenario

    d = tmp_path / "out"
    run_scenario("city", d, end=30, figures=False, equations=["epa_gasoline_car"])
    assert (d / "chain_vehicles.csv").is_file() and (d / "manifest.json").is_file()
    res = run_scenario("city", d, end=30, figures=False, equations=["vsp_ldv1999"])
    assert not (d / "chain_vehicles.csv").exists()
    listed = {f["path"] for f in json.loads((d / "manifest.json").read_text(encoding="utf-8"))["files"]}
    assert listed == {str(p.relative_to(d)) for p in d.rglob("*") if p.is_file()} - {"manifest.json"}
    (d / "notes.txt").write_text("mine", encoding="utf-8")
    with pytest.raises(OutputExists, match="notes.txt"):
        run_scenario("city", d, end=30, figures=False, equations=["vsp_ldv1999"])
    with pytest.raises(OutputExists, match="notes.txt"):
        res.write(d)
    res.write(d, force=True)
    assert (d / "notes.txt").read_text(encoding="utf-8") == "mine"
    assert "notes.txt" not in {f["path"] for f in json.loads((d / "manifest.json").read_text(encoding="utf-8"))["files"]}
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "data.csv").write_text("1,2\n", encoding="utf-8")
    with pytest.raises(OutputExists, match="not written by sumo-drvpw"):
        res.write(mine)
    res.write(tmp_path / "fresh")
    assert (tmp_path / "fresh" / "vehicles.parquet").is_file() and (tmp_path / "fresh" / "manifest.json").is_file()


def test_python_api_rewrite_keeps_its_files_whatever_the_file_system_clock(tmp_path, monkeypatch):
    """An earlier set's files were told from the new set's by their modification time
    against time.time() taken before writing; but a file's time is the file system's clock:
    Linux stamps a new file with its coarse tick, up to 7 ms behind time.time() here (2977
    of 3000 new files stamped before a time.time() read just before them), and a file
    server's clock may be seconds off. A set written again then lost the files it had just
    written (with this machine's clock 60 s ahead of the file system's: every file of
    RunResult.write and of run_scenario into its earlier folder). The files written again
    are kept, the earlier set's others still go, whatever either clock says."""
    import json
    import time

    from sumo_drvpw.sim import run_scenario

    d = tmp_path / "out"
    run_scenario("city", d, end=30, figures=False, equations=["epa_gasoline_car"])
    assert (d / "chain_vehicles.csv").is_file()
    real = time.time
    monkeypatch.setattr(time, "time", lambda: real() + 60.0)  # this machine's clock ahead of the files'

    def whole():  # the set's files all there, each listed; the earlier set's chain CSVs gone
        listed = {f["path"] for f in json.loads((d / "manifest.json").read_text(encoding="utf-8"))["files"]}
        assert {"vehicles.parquet", "edges.parquet", "summary.json"} <= listed
        assert {str(p.relative_to(d)) for p in d.rglob("*") if p.is_file()} == listed | {"manifest.json"}
        assert not (d / "chain_vehicles.csv").exists()

    res = run_scenario("city", d, end=30, figures=False, equations=["vsp_ldv1999"])
    whole()
    res.write(d)
    whole()


@pytest.mark.parametrize("kw,needle", [
    ({"terms": {"acc": float("nan"), "aero": 0.3}}, "must be a finite number, got nan"),
    ({"terms": {"acc": float("inf")}}, "must be a finite number"),
    ({"terms": {"acc": "1"}}, "must be a number, got '1'"),
    ({"terms": {"acc": 1.0}, "mass_kg": -3.0}, "mass_kg must be a vehicle mass"),
    ({"terms": {"acc": 1.0}, "vclasses": ("pasenger",)}, "not a SUMO vClass"),
    ({"terms": {"acc": 1.0}, "vclasses": "passenger"}, "vclasses must be a list")])
def test_an_equation_built_in_code_is_checked_as_a_file_is(kw, needle):
    """An Equation object with NaN booked NaN energy (and a valid term's 0), a string
    coefficient was read as a number, a negative mass booked negative energy, a misspelt or
    string vClass booked no vehicle — each silently (a rehearsal, 2026-11-29). Each is now a
    UserError naming the equation and the value, in a run and in an Accountant alike."""
    from sumo_drvpw.model.equations import Equation
    from sumo_drvpw.sim import run_scenario

    with pytest.raises(UserError, match=needle):
        run_scenario("city", None, end=5, figures=False, equations=[Equation("mine", **kw)])


def test_an_accountant_refuses_what_starts_sumo_and_books_the_built_ins_by_default():
    """Accountant(conn, equations=..., end=30, step_length=2) booked to wherever the script
    stepped at SUMO's own step length, saying nothing; with no equations at all it was refused
    (a rehearsal, 2026-11-29). Now the first is a UserError naming the overrides, the second
    books each vehicle by its class's built-in equations, as a bare SUMO config is run."""
    from pathlib import Path

    from sumo_drvpw.sim import Accountant, close_sumo, start_sumo
    from sumo_drvpw.sim.scenario import CONFIG_EQUATIONS, load_scenario

    city = Path(__file__).resolve().parent.parent / "scenarios" / "city.toml"
    conn = start_sumo(load_scenario(city, end=60).sumo_args)
    try:
        with pytest.raises(UserError, match="end, step_length start or step SUMO"):
            Accountant(conn, equations=["vsp_ldv1999"], end=30, step_length=2.0)
        acc = Accountant(conn)
        conn.addStepListener(acc)
        for _ in range(60):
            conn.simulationStep()
        res = acc.result()
    finally:
        close_sumo(conn)
    booked = set(res.vehicles.equation)
    assert booked and booked <= set(CONFIG_EQUATIONS) | {"epa_gasoline_car", "epa_diesel_car", "bmw_i3_battery"}
    assert "epa_gasoline_car" in booked  # the city's petrol cars: litres too


@pytest.mark.parametrize("spec", [42, None, 3.5])
def test_a_scenario_that_is_no_path_is_a_user_error(spec, tmp_path):
    """run_scenario(42) and Accountant(scenario=3) raised pathlib's TypeError; an out_dir that
    is a file raised FileExistsError (a rehearsal, 2026-11-29): each a UserError now."""
    from sumo_drvpw.sim import run_scenario

    with pytest.raises(UserError, match="give a scenario file, a SUMO config or a built-in"):
        run_scenario(spec)
    (tmp_path / "f.txt").write_text("x", encoding="utf-8")
    with pytest.raises(UserError, match="is a file; give a folder"):
        run_scenario("city", tmp_path / "f.txt", end=5)


def test_a_refused_run_leaves_the_earlier_set_and_a_code_built_fuel_chain_needs_its_engine(tmp_path):
    """A run refused before it starts (a [vtypes] of no vType) emptied the folder of the
    earlier set it was to replace; an EnergyChain(predicts='fuel') built in code booked a
    100 %-efficient petrol engine (a review, 2026-11-29)."""
    from sumo_drvpw.model.chain import EnergyChain
    from sumo_drvpw.model.equations import Equation
    from sumo_drvpw.sim import run_scenario

    d = tmp_path / "out"
    run_scenario("city", d, end=20, figures=False, equations=["vsp_ldv1999"])
    before = sorted(p.name for p in d.iterdir())
    cfg = (Path(__file__).resolve().parent.parent / "scenarios" / "city.sumocfg").as_posix()
    (tmp_path / "typo.toml").write_text(f'equations = ["vsp_ldv1999"]\n[sumo]\nconfig = "{cfg}"\n'
                                        '[vtypes.prius33]\nmass_kg = 1600\n', encoding="utf-8")
    with pytest.raises(UserError, match="prius33"):
        run_scenario(tmp_path / "typo.toml", d, end=20, figures=False)
    assert sorted(p.name for p in d.iterdir()) == before
    bare = Equation("bare", {"acc": 1.0, "roll": 0.01}, chain=EnergyChain(predicts="fuel"))
    with pytest.raises(UserError, match="marginal_efficiency is 1"):
        run_scenario("city", None, end=5, figures=False, equations=[bare])
