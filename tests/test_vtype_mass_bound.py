"""A road vehicle's vType mass beyond any road vehicle's is refused in one line naming the
file and the vType (a motorcycle of mass 1e9 booked 54,357 L over 0.5 km, exit 0: the bad-input
fuzz's finding); a road train's few hundred tonnes and a heavy train pass
(sim/vtypes.py ROAD_MASS_MAX_KG)."""

import pytest

from sumo_drvpw.errors import UserError
from sumo_drvpw.sim.vtypes import ROAD_MASS_MAX_KG, read_vtypes


def _file(tmp_path, vtype: str):
    p = tmp_path / "t.rou.xml"
    p.write_text(f"<routes>\n  {vtype}\n</routes>\n", encoding="utf-8")
    return p


@pytest.mark.parametrize("vtype", [
    '<vType id="m" vClass="motorcycle" mass="1e9"/>',
    '<vType id="m" vClass="trailer" mass="40000"><param key="loading" value="2e6"/></vType>',
    '<vType id="m"><param key="drvpw.mass" value="5e6"/></vType>',  # (no vClass: SUMO's passenger)
])
def test_a_road_vehicle_beyond_any_road_vehicle_s_mass_is_refused(tmp_path, vtype):
    p = _file(tmp_path, vtype)
    with pytest.raises(UserError, match=rf"{p}: vType 'm': mass .* beyond any road vehicle's"):
        read_vtypes([p])


@pytest.mark.parametrize("vtype, mass", [
    ('<vType id="m" vClass="trailer" mass="200000"/>', 200000.0),  # a quad road train
    ('<vType id="m" vClass="rail" mass="2e7"/>', 2e7),              # a 20,000-t ore train
])
def test_a_road_train_and_a_heavy_train_pass(tmp_path, vtype, mass):
    assert read_vtypes([_file(tmp_path, vtype)])["m"].mass_kg == mass
    assert mass <= ROAD_MASS_MAX_KG or "rail" in vtype


@pytest.mark.parametrize("vtype", [
    '<vType id="m" vClass="drone" mass="1e9"/>',      # exempt from the road bound since ba80741
    '<vType id="m" vClass="aircraft" mass="5e6"/>',   # 5,000 t: no aircraft (the heaviest some 640 t)
    '<vType id="m" vClass="rail" mass="1e30"/>',      # was booked: no bound at all off the road
    '<vType id="m" vClass="tram" mass="40000"><param key="loading" value="1e9"/></vType>',
    '<vType id="m" vClass="ship" mass="1e12"/>',
])
def test_a_vehicle_off_the_road_beyond_any_of_its_kind_is_refused(tmp_path, vtype):
    p = _file(tmp_path, vtype)
    with pytest.raises(UserError, match=rf"{p}: vType 'm': mass .* beyond any (drone|aircraft|rail|tram|ship)'s"):
        read_vtypes([p])


@pytest.mark.parametrize("vtype, mass", [
    ('<vType id="m" vClass="rail" mass="1e8"/>', 1e8),        # the heaviest trains run, some 100,000 t
    ('<vType id="m" vClass="ship" mass="4e8"/>', 4e8),        # a very large crude carrier, laden
    ('<vType id="m" vClass="aircraft" mass="6.4e5"/>', 6.4e5),  # an An-225 at take-off
])
def test_the_heaviest_trains_ships_and_aircraft_pass(tmp_path, vtype, mass):
    assert read_vtypes([_file(tmp_path, vtype)])["m"].mass_kg == mass


@pytest.mark.parametrize("vtype, refused", [
    ('<vType id="m" vClass="pedestrian" mass="7500"/>', True),   # 75.00 kg without its point
    ('<vType id="m" vClass="wheelchair" mass="600"/>', True),
    ('<vType id="m" vClass="pedestrian" mass="400"/>', False),   # the tests' heavy rider
    ('<vType id="m" vClass="wheelchair" mass="250"/>', False),
])
def test_a_person_s_vtype_beyond_any_person_s_mass_is_refused(tmp_path, vtype, refused):
    """A rider adds its vType's mass to its vehicle (live, as SUMO does, and in an FCD replay): a
    pedestrian vType of 7500 kg booked a car 7.5 t heavier (0.033 → 0.191 kWh over 200 m), and
    750 t passed the road bound (15.96 kWh), exit 0."""
    p = _file(tmp_path, vtype)
    if refused:
        with pytest.raises(UserError, match=rf"{p}: vType 'm': mass .* beyond any (pedestrian|wheelchair)'s \(at most 500"):
            read_vtypes([p])
    else:
        assert read_vtypes([p])["m"].mass_kg > 0


@pytest.mark.sumo
@pytest.mark.parametrize("where", ["route file", "scenario", "param"])
def test_a_vehicle_s_mass_in_tonnes_is_refused(tmp_path, capsys, where):
    """A truck vType written 6 (tonnes) where kg are meant was booked as a 6-kg truck (an FCD
    replay's truck: 0.040 kWh against 0.109 kWh at 6,000 kg), exit 0 (the bad-input fuzz's
    finding). A written mass below 1 % of its vClass's SUMO default (a truck's 4,500 kg) is
    refused in one line naming the vType and where the mass was written; 6,000 kg runs."""
    from pathlib import Path

    from sumo_drvpw.cli import main

    net = Path(__file__).resolve().parent.parent / "sumo_drvpw" / "sim" / "builtin" / "networks" / "city.net.xml"
    for mass, rc in (("6", 2), ("6000", 0)):
        d = tmp_path / mass
        d.mkdir()
        attr = f' mass="{mass}"' if where == "route file" else ""
        param = f'<param key="drvpw.mass" value="{mass}"/>' if where == "param" else ""
        (d / "r.rou.xml").write_text(
            f'<routes><vType id="tk" vClass="truck"{attr}>{param}</vType>'
            '<vehicle id="t0" type="tk" depart="0"><route edges="c00c10 c10c20"/></vehicle></routes>\n',
            encoding="utf-8")
        (d / "s.toml").write_text(
            f'equations = ["moves_single_unit_truck"]\n[sumo]\nnet = "{net}"\nroutes = ["r.rou.xml"]\nbegin = 0\n'
            'end = 20\nstep_length = 1.0\noptions = ["--no-warnings", "true"]\n[outputs]\nfigures = false\n'
            + (f'[vtypes.tk]\nmass_kg = {mass}\n' if where == "scenario" else ""), encoding="utf-8")
        assert main(["run", str(d / "s.toml"), "--out", str(d / "o")]) == rc
        err = capsys.readouterr().err
        if rc:
            said = {"route file": "its mass in", "scenario": "the scenario's mass_kg", "param": "its param drvpw.mass in"}[where]
            assert f"vType 'tk': mass 6 kg ({said}" in err and "below 1 % of a truck's (4,500 kg" in err
            assert len(err.strip().splitlines()) == 1 and not (d / "o").exists()


@pytest.mark.sumo
def test_a_copy_s_told_mass_in_tonnes_is_refused(tmp_path, capsys):
    """A setMass copy's mass told to an FCD replay ([vtypes."tk@t0"] mass_kg = 6, tonnes for
    kg) booked the truck from its 6th row at 6 kg (0.040 kWh against 0.109 kWh at 6,000 kg),
    exit 0: checked as a vType's written mass is (sim/scenario_values.tiny_mass), one line
    naming the copy and the key, no output; 6,000 kg runs."""
    import corpus
    from sumo_drvpw.cli import main

    for mass, rc in (("6", 2), ("6000", 0)):
        d = tmp_path / mass
        d.mkdir()
        argv = corpus._fcd_copy(d, f'[vtypes."tk@t0"]\nmass_kg = {mass}\n')
        assert main(argv) == rc
        err = capsys.readouterr().err
        if rc:
            assert f"vType 'tk@t0': mass 6 kg (vtypes.tk@t0.mass_kg in {d / 's.toml'})" in err, err
            assert "below 1 % of a truck's (4,500 kg" in err
            assert len(err.strip().splitlines()) == 1 and not (d / "o").exists()


def _rider_replay(d, tag: str, vtype: str, scenario: str = ""):
    """An FCD of car c0 carrying rider p0 (a ``tag``: person or container, of vType 'r' written
    ``vtype``) 20 s along the city's c00c10; the CLI's argv replaying it."""
    from pathlib import Path

    net = Path(__file__).resolve().parent.parent / "sumo_drvpw" / "sim" / "builtin" / "networks" / "city.net.xml"
    rows = "".join(f'<timestep time="{t}.00"><vehicle id="c0" x="{10.4 + 11 * t:.2f}" y="-1.60" angle="90.00" type="car" '
                   f'speed="11.00" pos="{7.2 + 11 * t:.2f}" lane="c00c10_0"/><{tag} id="p0" x="{10.4 + 11 * t:.2f}" '
                   f'y="-1.60" angle="90.00" type="r" speed="11.00" pos="{7.2 + 11 * t:.2f}" edge="c00c10"/></timestep>\n'
                   for t in range(20))
    d.mkdir()
    (d / "fcd.xml").write_text(f"<fcd-export>\n{rows}</fcd-export>\n", encoding="utf-8")
    (d / "t.rou.xml").write_text(f'<routes><vType id="car" vClass="passenger" mass="1500"/>{vtype}</routes>\n',
                                 encoding="utf-8")
    (d / "s.toml").write_text(f'equations = ["vsp_ldv1999"]\n[sumo]\nnet = "{net.as_posix()}"\nroutes = ["t.rou.xml"]\n'
                              + scenario, encoding="utf-8")
    return ["fcd", str(d / "fcd.xml"), "--scenario", str(d / "s.toml"), "--no-figures", "--no-progress",
            "--out", str(d / "o")]


@pytest.mark.sumo
@pytest.mark.parametrize("tag, vtype, usual", [
    ("container", '<vType id="r" vClass="truck" mass="2"/>', "a truck's (4,500 kg"),
    ("container", '<vType id="r" vClass="truck"><param key="vehicleMass" value="2"/></vType>', "a truck's (4,500 kg"),
    ("person", '<vType id="r" vClass="pedestrian" mass="0.07"/>', "a pedestrian's (70 kg"),
])
def test_a_rider_s_mass_in_tonnes_is_refused(tmp_path, capsys, tag, vtype, usual):
    """A rider's vType written in tonnes rode as kilograms, exit 0: a container of vClass truck
    written 2 for 2 t made its car 0.032 kWh against 0.074 kWh at 2,000 kg (an FCD replay; a
    live run reads the same files). Refused in one line naming the vType, its file and the
    vClass's default, no output; written in kg it runs."""
    from sumo_drvpw.cli import main

    d = tmp_path / "t"
    assert main(_rider_replay(d, tag, vtype)) == 2
    err = capsys.readouterr().err
    assert "vType 'r': mass " in err and f"(its {'param vehicleMass' if 'vehicleMass' in vtype else 'mass'} in {d / 't.rou.xml'})" in err and usual in err, err
    assert len(err.strip().splitlines()) == 1 and not (d / "o").exists()
    kg = vtype.replace('"0.07"', '"70"').replace('"2"', '"2000"')
    assert main(_rider_replay(tmp_path / "kg", tag, kg)) == 0


@pytest.mark.sumo
def test_a_vehicle_s_mass_in_tonnes_the_scenario_corrects_still_runs(tmp_path):
    """A file's truck written 6 (t) that the scenario books at [vtypes.tk] mass_kg = 6000 runs:
    the scenario's mass is the vehicle's (the file's is no rider's)."""
    from sumo_drvpw.cli import main

    argv = _rider_replay(tmp_path / "t", "person", '<vType id="tk" vClass="truck" mass="6"/>',
                         '[vtypes.car]\nmass_kg = 1500\n[vtypes.tk]\nmass_kg = 6000\n')
    assert main(argv) == 0


@pytest.mark.sumo
@pytest.mark.parametrize("vtype", ['<vType id="r" vClass="container" mass="5"/>',   # a 5-kg parcel riding
                                   '<vType id="r" vClass="container"/><vType id="uav" vClass="drone" mass="2"/>'])
def test_a_light_vtype_of_a_class_without_a_mass_of_its_own_runs(tmp_path, vtype):
    """SUMO gives a container's, a drone's vClass no mass of its own (getMass: the generic 1,500
    kg), so a 5-kg parcel riding in a car, or a 2-kg drone vType in the files, is no tonne written
    as a kg: the run goes on (refused since the riders' check, 'below 1 % of a container's
    (1,500 kg)')."""
    from sumo_drvpw.cli import main

    assert main(_rider_replay(tmp_path / "t", "container", vtype)) == 0


@pytest.mark.sumo
def test_a_booked_vehicle_of_a_class_without_a_mass_of_its_own_runs(tmp_path):
    """A 2-kg drone a drone equation books is no tonne written as a kg either: SUMO gives its
    vClass no mass of its own (the generic 1,500 kg). 26a965c let the vType pass the riders'
    check but the booked vehicle's (sim/resolver.py, tiny_mass) still refused it: 'vType 'uav':
    mass 2 kg (its mass in …) is below 1 % of a drone's (1,500 kg, SUMO's default)', exit 2."""
    import json

    from sumo_drvpw.cli import main

    d = tmp_path / "t"
    argv = _rider_replay(d, "container", '<vType id="r" vClass="container"/><vType id="uav" vClass="drone" mass="2"/>')
    (d / "fcd.xml").write_text((d / "fcd.xml").read_text(encoding="utf-8").replace('type="car"', 'type="uav"'),
                               encoding="utf-8")
    (d / "drone.toml").write_text('[equation]\nname = "dronevsp"\nvclasses = ["drone"]\n[terms]\nacc = 1.0\nm_v1 = 0.1\n',
                                  encoding="utf-8")
    (d / "s.toml").write_text((d / "s.toml").read_text(encoding="utf-8").replace('"vsp_ldv1999"', '"drone.toml"'),
                              encoding="utf-8")
    assert main(argv) == 0
    assert json.loads((d / "o" / "summary.json").read_text())["vehicles"] == 1
