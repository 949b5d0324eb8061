"""Quirks of real public drive logs a new user met (docs/adapters.md "Data quirks"),
each reproduced on a small synthetic file: an app's title lines above the CSV header,
header labels with a leading space copied into the mapping, …"""

from __future__ import annotations

import numpy as np
import pytest

from sumo_drvpw.data.adapters import read
from sumo_drvpw.errors import UserError

# BlueDriver's export (and others): title lines above the header, labels after ', '
TITLED = ("BlueDriver Data Log,,\n"
          "07/16/2017, 2017 2:47:57 PM,\n"
          "Time (s), Engine RPM (rpm), Vehicle Speed (km/h)\n"
          "0, , \n"
          "1.5,838,36\n"
          "3,814,72\n")
MAP = ('[columns."Time (s)"]\nname = "time_s"\n'
       '[columns." Vehicle Speed (km/h)"]\nname = "speed_mps"\nunit = "km/h"\n')


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


def test_mapping_label_with_the_headers_leading_space_names_the_column(tmp_path):
    """A label copied verbatim from a ', '-separated header (' Vehicle Speed (km/h)') is the
    column the reader sees stripped ('Vehicle Speed (km/h)'), not a missing one."""
    src = _write(tmp_path, "log.csv", TITLED.split("\n", 2)[2])
    df, rep = read("columns", [src], columns=_write(tmp_path, "m.toml", MAP))
    np.testing.assert_allclose(df["speed_mps"], [10.0, 20.0])   # 36, 72 km/h
    assert rep["dropped"] == {"NaN speed": 1}                   # the row of blank ' ' cells
    both = MAP + '[columns."Vehicle Speed (km/h)"]\nname = "gps_speed_mps"\nunit = "km/h"\n'
    with pytest.raises(UserError, match="name the same source column"):
        read("columns", [src], columns=_write(tmp_path, "m2.toml", both))


def test_title_lines_above_the_header_skip_rows_and_the_hint(tmp_path):
    src = _write(tmp_path, "log.csv", TITLED)
    with pytest.raises(UserError, match=r"on line 3.*set options.skip_rows = 2 in .*m.toml"):
        read("columns", [src], columns=_write(tmp_path, "m.toml", MAP))
    df, _ = read("columns", [src], columns=_write(tmp_path, "s.toml", "[options]\nskip_rows = 2\n" + MAP))
    np.testing.assert_allclose(df["time_s"], [1.5, 3.0])
    np.testing.assert_allclose(df["engine_rpm_rpm"], [838, 814])
    one_wide = _write(tmp_path, "one.csv", "My logger v2\nTime (s),Vehicle Speed (km/h)\n0,36\n1,72\n")
    with pytest.raises(UserError, match=r"set options.skip_rows = 1"):  # a parser error, hinted
        read("columns", [one_wide], columns=_write(tmp_path, "m.toml", MAP))
    for bad in ("-1", "true", "1.5", '"2"'):
        with pytest.raises(UserError, match="options.skip_rows must be a whole number"):
            read("columns", [src], columns=_write(tmp_path, "b.toml", f"[options]\nskip_rows = {bad}\n" + MAP))


# A petrol car's Torque Pro log (yudhi-chen/OBD_viewer): speed and the app's fuel flow, no
# driving power; the user first runs the wheel-level commands on it
def _fuel_log(tmp_path):
    t = np.arange(0.0, 120.0, 1.0)
    v = 10.0 + 5.0 * np.sin(t / 10.0)
    rows = "\n".join(f"trip,{a:g},{b:.3f},{1.0 + 0.2 * b:.3f}" for a, b in zip(t, v))
    return _write(tmp_path, "fuel.csv", "trip_id,time_s,speed_mps,fuel_flow_rate_hour_lph\n" + rows + "\n")


# The RSK Renault Twizy logs (NaitMalekYoussef/RSK_Twizy_EV_Dataset, CC-BY-4.0): speed and the
# BMS's state of charge, imported with options.soc_capacity_kwh into the battery's energy
# counters, no V·I: the wheel-level commands name the battery target the log does hold
def _counter_log(tmp_path):
    t = np.arange(0.0, 120.0, 1.0)
    v = 10.0 + 5.0 * np.sin(t / 10.0)
    dis = np.cumsum(np.full(t.size, 2000.0))
    rows = "\n".join(f"trip,{a:g},{b:.3f},{c:.1f},0" for a, b, c in zip(t, v, dis))
    return _write(tmp_path, "soc.csv", "trip_id,time_s,speed_mps,battery_discharge_energy_j,"
                  "battery_charge_energy_j\n" + rows + "\n")


_FUEL = "it holds fuel_flow_rate_hour_lph"
_COUNTERS = "battery_discharge_energy_j"


@pytest.mark.parametrize("make,holds,argv,want", [
    (_fuel_log, _FUEL, ["calibrate"], "calibrate its fuel chain with `sumo-drvpw calibrate LOG --vehicle V --target fuel"),
    (_fuel_log, _FUEL, ["compare", "--equation", "vsp_spec"], "then compare or diagnose with --target fuel"),
    (_fuel_log, _FUEL, ["diagnose"], "calibrate its fuel chain with"),
    (_fuel_log, _FUEL, ["calibrate", "--target", "fuel"], "give it with --equation (vsp_spec"),
    (_fuel_log, _FUEL, ["calibrate", "--target", "fuel", "--engine", "memory"], "give it with --equation (vsp_spec"),
    (_counter_log, _COUNTERS, ["calibrate"],
     "calibrate its battery chain with `sumo-drvpw calibrate LOG --vehicle V --target battery"),
    (_counter_log, _COUNTERS, ["compare", "--equation", "vsp_spec"], "then compare or diagnose with --target battery"),
    (_counter_log, _COUNTERS, ["diagnose"], "calibrate its battery chain with"),
])
def test_a_log_without_driving_power_is_told_its_fuel_or_battery_target(tmp_path, capsys, make, holds, argv, want):
    from sumo_drvpw.cli import main as cli_main

    log = make(tmp_path)
    out = tmp_path / ("o.toml" if argv[0] == "calibrate" else "o")
    code = cli_main([argv[0], str(log), *argv[1:], "--vehicle", "prius3", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert "no measured power" in err and holds in err and want in err
    assert not out.exists()


def test_no_driving_power_crosses_a_task_boundary_whole():
    """A Dask task's refusal is pickled to the driver: it stays a NoDrivingPower with its targets."""
    import pickle

    from sumo_drvpw.errors import NoDrivingPower
    from sumo_drvpw.fit.engine import guarded, unguarded

    def refuse():
        raise NoDrivingPower("x.csv: no measured power", ("fuel",))

    with pytest.raises(NoDrivingPower) as e:
        unguarded(pickle.loads(pickle.dumps(guarded(refuse))))
    assert e.value.targets == ("fuel",) and str(e.value) == "x.csv: no measured power"
    assert pickle.loads(pickle.dumps(e.value)).targets == ("fuel",)


# LeafSpy (a Nissan Leaf's phone logger, euw15/NissanLeafSpy_DataCapture): a signed speed —
# backing up is negative —, −3.6 km/h logged for 'no reading' while the car regenerates at
# speed, and status columns that are text in some files and numbers in others
LEAF_MAP = ('[options]\ntime_unit = "datetime"\n'
            '[columns."Date/Time"]\nname = "time_s"\n'
            '[columns."Speed"]\nname = "speed_mps"\nunit = "km/h"\n')


def _leaf(tmp_path, name, speeds, status=None):
    rows = [f"05/20/2017 14:{7 + (5 * i) // 60:02d}:{(5 * i) % 60:02d},{v},{'' if status is None else status[i]}"
            for i, v in enumerate(speeds)]
    return _write(tmp_path, name, "Date/Time,Speed,GPS Status\n" + "\n".join(rows) + "\n")


def test_a_signed_speed_backing_up_is_read_as_reversing(tmp_path):
    m = _write(tmp_path, "m.toml", LEAF_MAP)
    fwd = [0.0, 10.0, 20.0, 30.0, 30.0, 20.0, 10.0, 0.0, 5.0, 10.0, 10.0] + [30.0] * 30 + [10.0, 0.0, 0.0]
    src = _leaf(tmp_path, "park.csv", fwd[:8] + [-0.5, -1.3, -0.7] + fwd[11:])
    df, rep = read("columns", [src], columns=m)
    np.testing.assert_allclose(df["speed_mps"].iloc[8:11], np.array([0.5, 1.3, 0.7]) / 3.6)
    assert df["reverse"].tolist() == [False] * 8 + [True] * 3 + [False] * 33
    assert any("3 sample(s) with a negative speed" in n and "reversing" in n for n in rep["files"][0]["notes"])
    for speeds, why in (([-x for x in fwd], "mostly negative: a wrong sign"),
                        (fwd[:8] + [-50.0] + fwd[9:], "faster than a car backs up")):
        with pytest.raises(UserError, match=r"outside \[0, 100\] m/s: wrong unit or sign\?"):
            read("columns", [_leaf(tmp_path, "bad.csv", speeds)], columns=m)


def test_a_repeated_negative_speed_is_a_no_reading_value_not_reversing(tmp_path):
    speeds = [0.0, 10.0, 20.0, 30.0, 43.5, -3.6, -3.6, -3.6, 43.5, 38.0, 30.0, 20.0, 10.0, 5.0, 0.0,
              0.0, 10.0, 20.0, 30.0, 40.0, 40.0, 40.0, 40.0, 40.0, 40.0, 40.0, 40.0, 40.0, 40.0, 0.0]
    src = _leaf(tmp_path, "sentinel.csv", speeds)
    with pytest.raises(UserError, match=r"'no reading' value: every negative speed, 3 sample\(s\).*na_values"):
        read("columns", [src], columns=_write(tmp_path, "m.toml", LEAF_MAP))
    own = LEAF_MAP.replace('unit = "km/h"\n', 'unit = "km/h"\nna_values = [-3.6]\n')
    df, rep = read("columns", [src], columns=_write(tmp_path, "own.toml", own))
    assert len(df) == 27 and rep["dropped"] == {"NaN speed": 3} and "reverse" not in df
    assert any("'Speed': 3 cell(s) held its 'no reading' value (-3.6)" in n for n in rep["files"][0]["notes"])
    with pytest.raises(UserError, match=r"columns.Speed.na_values must be a number or text"):
        read("columns", [src], columns=_write(tmp_path, "b.toml", own.replace("[-3.6]", "[true]")))


def test_a_column_text_in_one_file_and_numbers_in_another_is_kept_as_text(tmp_path):
    """Before: the Parquet writer failed with a traceback (ArrowTypeError: expected bytes,
    got a 'float' object) on LeafSpy's 'GPS Status'."""
    from sumo_drvpw.cli import main as cli_main

    d = tmp_path / "logs"
    d.mkdir()
    speeds = [0.0, 10.0, 20.0, 10.0, 0.0]
    _leaf(d, "a.csv", speeds, status=["none", "none", "fix", "fix", "none"])
    _leaf(d, "b.csv", speeds, status=[0, 1, 1, 1, 0])
    m = _write(tmp_path, "m.toml", LEAF_MAP)
    out = tmp_path / "leaf.parquet"
    assert cli_main(["import", "columns", str(d), "--columns", str(m), "--out", str(out)]) == 0
    import pandas as pd

    df = pd.read_parquet(out)
    assert df["gps_status"].tolist() == ["none", "none", "fix", "fix", "none", "0.0", "1.0", "1.0", "1.0", "0.0"]
    from sumo_drvpw.cli.import_ import read_report

    assert any("'gps_status' is text in 1 file(s) (a.csv) and numbers in others" in n
               for n in read_report(out)["notes"])


def test_a_folder_where_one_file_backs_up_reads_as_a_drive_log(tmp_path):
    """The reverse flag of one file is 'not set' in the others, in the import and in a log
    whose flag column has gaps (before: 'column reverse must be boolean, got None')."""
    import pandas as pd

    from sumo_drvpw.cli import main as cli_main
    from sumo_drvpw.data.log import read_log

    d = tmp_path / "logs"
    d.mkdir()
    fwd = [0.0, 10.0, 20.0, 30.0] + [30.0] * 30 + [10.0, 0.0]
    _leaf(d, "a.csv", fwd[:2] + [-0.5, -1.0] + fwd[4:])
    _leaf(d, "b.csv", fwd)
    out = tmp_path / "leaf.parquet"
    assert cli_main(["import", "columns", str(d), "--columns", str(_write(tmp_path, "m.toml", LEAF_MAP)),
                     "--out", str(out)]) == 0
    log = read_log(out)
    assert log.counts["excluded_reverse"] == 2 and pd.read_parquet(out)["reverse"].dtype == bool
    gappy = pd.read_parquet(out).astype({"reverse": object})
    gappy.loc[gappy["trip_id"] == "b", "reverse"] = None
    gappy.to_parquet(tmp_path / "gappy.parquet")
    assert read_log(tmp_path / "gappy.parquet").counts["excluded_reverse"] == 2


def test_a_standstill_that_draws_driving_power_is_a_lost_speed_signal(tmp_path):
    """LeafSpy logged speed 0 for minutes while the battery gave 74 kW and took 13 kW back
    (euw15/NissanLeafSpy_DataCapture, 2017-10-31): such a 'standstill' is driving. Its whole
    stretch is left out (its low-power samples are cruising, not auxiliaries) and counted; a
    real stop drawing a heater's 6 kW, one spike, and a charging stop are not."""
    from sumo_drvpw.data.charging import DRIVE_MIN_W, speed_dropout_mask
    from sumo_drvpw.data.measured import load_measured

    n = 400
    t = np.arange(n) * 1.0
    v = np.full(n, 2.0)                                       # slow: no km/h-like jumps
    p = np.full(n, 8000.0)
    v[50:100], p[50:100] = 0.0, 6000.0                       # a stop with the heater on
    v[120:130], p[120:130] = 0.0, 500.0
    p[125] = 40000.0                                          # one spike
    v[200:300] = 0.0                                          # speed lost while driving:
    p[200:300] = np.where(np.arange(100) % 4 == 0, 60000.0, np.where(np.arange(100) % 4 == 1, -13000.0, 4000.0))
    v[330:360], p[330:360] = 0.0, -40000.0                   # a fast charger
    m = speed_dropout_mask(p, v, np.zeros(n, int), t)
    assert np.flatnonzero(m).tolist() == list(range(200, 300)) and DRIVE_MIN_W > 7000.0
    # a 10-Hz OBD log whose speed lags the power by 1.5 s: at each stop the car still brakes
    # (−20 kW) and at each start already pulls away (50 kW) while its speed reads 0 — no dropout
    tl = np.arange(600) * 0.1
    vl, pl = np.full(600, 8.0), np.full(600, 12000.0)
    vl[100:400], pl[100:400] = 0.0, 500.0
    pl[100:115], pl[385:400] = -20000.0, 50000.0
    # an e-bus at a stop with 25 kW of air conditioning for 5 minutes: a large load, no braking
    tb = np.arange(400) * 1.0
    vb, pb = np.full(400, 8.0), np.full(400, 60000.0)
    vb[50:350], pb[50:350] = 0.0, 25000.0
    for tt, vv, pp in ((tl, vl, pl), (tb, vb, pb)):
        assert not speed_dropout_mask(pp, vv, np.zeros(len(tt), int), tt).any()
    # the same stretches read as a lost speed without those guards (the rule of 4baf5a0)
    assert speed_dropout_mask(pl, vl, np.zeros(600, int), tl, min_s=0.0).any()
    assert speed_dropout_mask(pb, vb, np.zeros(400, int), tb, brake_w=-np.inf).any()
    rows = "\n".join(f"T,{a:g},{b:g},360,{c / 360:.4f}" for a, b, c in zip(t, v, p))
    log = _write(tmp_path, "bev.csv", "trip_id,time_s,speed_mps,battery_voltage_v,battery_current_a\n" + rows + "\n")
    for target in ("battery", "wheel"):
        mm = load_measured([log], "bmw_i3", target=target)
        assert mm.log.counts["excluded_speed_dropout"] == 100
        assert not mm.usable[200:300].any() and mm.usable[50:100].all()


def test_a_few_glitch_values_out_of_range_are_named_as_such(tmp_path):
    from sumo_drvpw.data.log import read_log

    n = 300
    amb = np.full(n, 25.0)
    amb[[40, 41]] = 95.0                                       # LeafSpy's 203 °F
    rows = "\n".join(f"T,{i},5.0,{a:g}" for i, a in enumerate(amb))
    p = _write(tmp_path, "a.csv", "trip_id,time_s,speed_mps,ambient_c\n" + rows + "\n")
    with pytest.raises(UserError, match=r"of the 300 values read with it, 2 are outside \(95\), the rest in "
                                        r"\[25, 25\].*na_values"):
        read_log(p)
    rows = "\n".join(f"T,{i},5.0,{a + 273.15:g}" for i, a in enumerate(np.full(n, 25.0)))
    k = _write(tmp_path, "k.csv", "trip_id,time_s,speed_mps,ambient_c\n" + rows + "\n")
    with pytest.raises(UserError, match=r"in K\? subtract 273.15"):                # a wrong unit
        read_log(k)


def test_small_trips_keep_their_error_but_do_not_swamp_the_mean():
    """A folder of LeafSpy files holds files logged while parked: a trip of 0.002 kWh predicted
    at 0.04 kWh (+1600 %) made compare's mean per-trip error 53 % where the trips that drove
    scored 14 %."""
    from sumo_drvpw.fit.trip_energy import SMALL_TRIP_SHARE, trip_energy_doc
    from sumo_drvpw.report.format import partial_trip_lines

    kwh = 3.6e6
    doc = trip_energy_doc(["a", "b", "c", "parked"], np.array([2.0, 3.0, 4.0, 0.002]) * kwh,
                          np.array([2.2, 2.7, 4.0, 0.036]) * kwh)
    assert doc["trips"]["parked"]["error"] == pytest.approx(17.0)          # kept per trip
    assert doc["small_trips"] == ["parked"] and doc["small_trip_share"] == SMALL_TRIP_SHARE
    assert doc["mean_abs_error"] == pytest.approx((0.1 + 0.1 + 0.0) / 3)
    assert doc["max_abs_error"] == pytest.approx(0.1)
    assert any(line.startswith("**Small trips**: 1 trip(s)") and "parked" in line for line in partial_trip_lines(doc))
    even = trip_energy_doc(["a", "b"], np.array([2.0, 3.0]) * kwh, np.array([2.2, 2.7]) * kwh)
    assert "small_trips" not in even and partial_trip_lines(even) == []


def test_a_continuation_file_without_header_is_named_as_such(tmp_path):
    """LeafSpy continues a log in a '_2' file without its header (4 of 209 files)."""
    m = _write(tmp_path, "m.toml", LEAF_MAP)
    cont = _write(tmp_path, "log_2.csv", "04/06/2017 8:14:52,0.0,\n04/06/2017 8:14:57,2.7,\n")
    with pytest.raises(UserError, match=r"missing column 'Date/Time'.*its first line is data, not a header: "
                                        r"'04/06/2017 8:14:52,0.0.*put the header line of its other files above it"):
        read("columns", [cont], columns=m)
    other = _write(tmp_path, "other.csv", "Zeit,Tempo\n0,1\n1,2\n")
    with pytest.raises(UserError, match=r"missing column 'Date/Time' named in .*m.toml$"):
        read("columns", [other], columns=m)


def test_an_elevation_that_is_noise_is_called_noise(tmp_path, capsys):
    """A phone's GPS altitude on a flat coastal route (yudhi-chen/OBD_viewer, Torque Pro):
    −63 … +224 m, 6.7 % of the samples steeper than any road; the rest's grade noise was
    booked as climbs (a fuel chain's idle 2.5 L/h and 66 % engine efficiency, IMPLAUSIBLE).
    One glitch stays a glitch."""
    from sumo_drvpw.cli import note_counts
    from sumo_drvpw.data.log import read_log

    rng = np.random.default_rng(7)
    n = 1000
    jumps = 60.0 * ((np.arange(n) // 40) % 2) + rng.normal(0.0, 3.0, n)   # a GPS altitude hopping 60 m
    for name, z, noisy in (("noisy", jumps, True),
                           ("glitch", np.r_[np.full(500, 10.0), 60.0, np.full(n - 501, 10.0)], False)):
        rows = "\n".join(f"T,{i},5.0,{e:.1f}" for i, e in enumerate(z))
        log = read_log(_write(tmp_path, f"{name}.csv", "trip_id,time_s,speed_mps,elevation_m\n" + rows + "\n"))
        assert log.counts["excluded_grade_outlier"] > 0
        note_counts(log.counts)
        out = capsys.readouterr().out
        assert ("the elevation is noise, not glitches" in out) is noisy, out


@pytest.mark.parametrize("encoding,said", [
    ("", "(its UTF-8 written twice over: map that label as it reads)"),
    ('encoding = "latin-1"\n', '(UTF-8 read as Latin-1: [options] encoding = "utf-8", or map that label)')])
def test_a_label_mis_encoded_by_the_logger_or_the_reading_is_named(tmp_path, encoding, said):
    """KIT's 2017 OBD logs write '°C' as 'Â°C' (their UTF-8 encoded twice); a mapping of the
    clean label was refused as a missing column with no pointer to the label the file has.
    Now the near label is named, and what to do: read as UTF-8 where a Latin-1 reading made
    it, map the label as it reads where the file holds it so."""
    m = _write(tmp_path, "m.toml", f"[options]\n{encoding}" + '[columns."t [s]"]\nname = "time_s"\n'
               '[columns."v [km/h]"]\nname = "speed_mps"\nunit = "km/h"\n'
               '[columns."Ambient [°C]"]\nname = "ambient_c"\nunit = "°C"\n')
    f = tmp_path / "log.csv"
    head = "t [s],v [km/h],Ambient [°C]\n" if encoding else "t [s],v [km/h],Ambient [Â°C]\n"
    f.write_bytes((head + "0,0,4\n1,3.6,4\n").encode("utf-8"))
    with pytest.raises(UserError) as e:
        read("columns", [f], columns=m)
    assert "missing column 'Ambient [°C]'" in str(e.value) and "the file has 'Ambient [Â°C]'" in str(e.value)
    assert said in str(e.value), str(e.value)


def test_a_log_of_held_values_is_said_to_overstate_its_samples(tmp_path, capsys):
    """An OBD log at ~11 rows/s whose values are new about once a second (a rehearsal's KIT
    Seat Leon, 2026-11-29: standard errors 3.3× smaller than on every 10th row, nothing said).
    calibrate now notes the share of held rows and how much the errors are understated; a
    log of fresh values says nothing."""
    import numpy as np
    import pandas as pd

    from sumo_drvpw.cli import main as cli_main

    rng = np.random.default_rng(2)
    n = 6000
    t = np.arange(n) * 0.1
    v = 12 + 6 * np.sin(t / 30.0)
    a = 0.2 * np.cos(t / 30.0)
    p = 1.1 * 1400 * v * a + 130 * v + 0.4 * v ** 3 + rng.normal(0, 500, n)
    fresh = pd.DataFrame({"time_s": t, "speed_mps": v, "accel_mps2": a, "power_w": p, "mass_kg": 1400.0})
    held = fresh.copy()
    cols = ["speed_mps", "accel_mps2", "power_w"]
    held[cols] = fresh[cols].to_numpy()[(np.arange(n) // 10) * 10]
    for name, df, said in (("fresh", fresh, False), ("held", held, True)):
        df.to_csv(tmp_path / f"{name}.csv", index=False)
        capsys.readouterr()
        assert cli_main(["calibrate", str(tmp_path / f"{name}.csv"), "--out", str(tmp_path / f"{name}.toml")]) == 0
        out = capsys.readouterr().out
        assert ("repeat the row before" in out) == said, out
        if said:
            assert "90% of the moving rows" in out and "about one new value per 10.0 rows" in out and "3.2×" in out


