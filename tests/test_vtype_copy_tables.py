"""A scenario's ``[vtypes."<type>@<id>"]`` (a vehicle's own vType copy, made by a script's
setMass): it tells the copy's mass, and nothing else — the vehicle keeps its type's equations
and cold start, live and replayed (sim/loop.py check_types) — so another key is refused, not
silently left unread (sim/run.py check_vtype_tables)."""

from types import SimpleNamespace

import pytest

from sumo_drvpw.errors import UserError
from sumo_drvpw.sim.run import check_vtype_tables
from sumo_drvpw.sim.vtypes import read_vtypes


def _files(tmp_path):
    r = tmp_path / "r.rou.xml"
    r.write_text('<routes><vType id="car" vClass="passenger"/></routes>\n', encoding="utf-8")
    return read_vtypes([r])


@pytest.mark.parametrize("entry, says", [({"mass_kg": 900.0, "equations": ["vsp_ldv1999"]}, "got equations"),
                                         ({"cold_start": 1.0}, "got cold_start")])
def test_a_copy_given_more_than_its_mass_is_refused(tmp_path, entry, says):
    sc = SimpleNamespace(path="s.toml", vtype_data={'car@v': entry})
    with pytest.raises(UserError, match=r"s\.toml: \[vtypes\.car@v\] is a vehicle's own vType copy") as e:
        check_vtype_tables(sc, _files(tmp_path))
    assert says in str(e.value) and "[vtypes.car]" in str(e.value)


def test_a_copy_s_mass_and_a_type_s_every_key_are_taken(tmp_path):
    sc = SimpleNamespace(path="s.toml", vtype_data={"car@v": {"mass_kg": 900.0},
                                                    "car": {"mass_kg": 1400.0, "equations": ["x"], "cold_start": 1.0}})
    check_vtype_tables(sc, _files(tmp_path))
