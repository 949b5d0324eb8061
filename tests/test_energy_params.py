"""A vType's own SUMO Energy-model parameters as an equation with a battery chain
(model/energy_params.py): the inverse of export-vtype, by hand, and against SUMO 1.28
itself (its defaults)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sumo_drvpw.model.energy_params import energy_params_equation
from sumo_drvpw.model.terms import Inputs
from sumo_drvpw.sim import close_sumo, start_sumo
from sumo_drvpw.sim.export import energy_model_params

REPO = Path(__file__).resolve().parent.parent
HW_NET = REPO / "sumo_drvpw" / "sim" / "builtin" / "networks" / "highway.net.xml"


def _one(params: dict, mass=None):
    return energy_params_equation("x", params, mass, "f.xml: vType 'x'")


def test_params_to_equation_and_back_is_exact():
    """The inverse exactly: parameters → equation → export's parameters are the same."""
    p = {"frontSurfaceArea": 2.2, "airDragCoefficient": 0.31, "rollDragCoefficient": 0.0115,
         "rotatingMass": 75.0, "constantPowerIntake": 650.0, "propulsionEfficiency": 0.91,
         "recuperationEfficiency": 0.74, "radialDragCoefficient": 0.0}
    eq, notes = _one({k: str(v) for k, v in p.items()}, 1540.0)
    assert notes == []
    back, missing = energy_model_params(eq, frontal_area_m2=2.2)
    assert [m for m in missing if "grade" not in m] == []
    for k, v in p.items():
        assert back[k] == pytest.approx(v, rel=1e-12, abs=1e-12), k
    assert back["mass"] == 1540.0


def test_power_and_battery_energy_by_hand():
    """A vType's parameters and a trace (15 m/s for 10 s, up to 20 m/s at 1 m/s², back at
    −1 m/s², 1-s steps, flat, no wind): the evaluator's power and battery energy equal
    SUMO's formula worked by hand (HelpersEnergy.cpp; g 9.80665, ρ 1.2041)."""
    m, rot, A, cd, cr, aux, et, er = 1500.0, 60.0, 2.2, 0.3, 0.012, 500.0, 0.9, 0.7
    params = {"frontSurfaceArea": A, "airDragCoefficient": cd, "rollDragCoefficient": cr,
              "rotatingMass": rot, "constantPowerIntake": aux, "propulsionEfficiency": et,
              "recuperationEfficiency": er}
    eq, _ = _one(params, m)
    v = np.array([15.0] * 10 + [16, 17, 18, 19, 20] + [19, 18, 17, 16, 15])
    v_prev = np.concatenate([[15.0], v[:-1]])
    a = v - v_prev
    z = np.zeros_like(v)
    x = Inputs(v=v, a=a, theta=z, wind=z, mass=np.full_like(v, 999.0), rho=np.full_like(v, 1.1),
               v_acc=(v + v_prev) / 2)
    p = eq.power(x)
    hand = (0.5 * (m + rot) * (v ** 2 - v_prev ** 2) + 0.5 * 1.2041 * A * cd * v ** 3
            + cr * 9.80665 * m * v)
    np.testing.assert_allclose(p, hand, rtol=1e-12)
    bat = eq.chain.evaluate(p, v, dt_s=1.0)["power_w"]
    hand_bat = np.where(hand > 0, hand / et, hand * er) + aux
    np.testing.assert_allclose(bat, hand_bat, rtol=1e-12)
    assert (hand < 0).any() and (hand > 0).any()
    # the run's air density and a vehicle's own mass do not enter: SUMO's are fixed
    assert bat.sum() == pytest.approx(hand_bat.sum(), rel=1e-12)


def test_defaults_are_sumos_own():
    """One parameter written: the rest are SUMO 1.28's defaults. Checked against SUMO
    itself: three vTypes (only airDragCoefficient; only the deprecated
    internalMomentOfInertia and vehicleMass; a bus with a mass and only
    constantPowerIntake) driven at set speeds (10 m/s, up to 20 at 2 m/s², back) on the
    straight flat highway: SUMO's electricity per step (getElectricityConsumption × 3600)
    equals our equation's battery power to 1e-9 in every step. A vType SUMO's defaults
    book differently (frontSurfaceArea from width × height, the bus class's mass) would
    differ by 20 % and more."""
    types = {"cd": ({"airDragCoefficient": "0.28"}, None, "passenger"),
             "old": ({"internalMomentOfInertia": "300", "vehicleMass": "2000"}, None, "passenger"),
             "bus": ({"constantPowerIntake": "2500"}, "12000", "bus")}
    rou = ["<routes>"]
    for vt, (params, mass, vc) in types.items():
        m = f' mass="{mass}"' if mass else ""
        rou.append(f'<vType id="{vt}" vClass="{vc}" emissionClass="Energy/unknown"{m} accel="5" '
                   'decel="9" sigma="0" maxSpeed="40">'
                   + "".join(f'<param key="{k}" value="{v}"/>' for k, v in params.items()) + "</vType>")
    rou.append('<route id="r" edges="e01 e12"/>')
    rou += [f'<vehicle id="{vt}" type="{vt}" route="r" depart="{i * 3}" departSpeed="10" '
            f'departLane="{i % 2}"/>' for i, vt in enumerate(types)]
    import tempfile

    sched = [10.0] * 3 + [12, 14, 16, 18, 20, 20, 20, 18, 16, 14, 12, 10, 10]
    got: dict[str, list] = {vt: [] for vt in types}
    with tempfile.TemporaryDirectory() as d:
        (Path(d) / "r.rou.xml").write_text("\n".join(rou + ["</routes>"]), encoding="utf-8")
        conn = start_sumo(["-n", str(HW_NET), "-r", str(Path(d) / "r.rou.xml"), "--step-length", "1",
                           "--no-warnings", "true"])
        try:
            for _ in range(24):
                conn.simulationStep()
                for vid in conn.vehicle.getIDList():
                    k = len(got[vid])
                    got[vid].append((conn.vehicle.getSpeed(vid), conn.vehicle.getSlope(vid),
                                     conn.vehicle.getElectricityConsumption(vid) * 3600.0))
                    conn.vehicle.setSpeedMode(vid, 0)
                    conn.vehicle.setSpeed(vid, sched[min(k + 1, len(sched) - 1)])
        finally:
            close_sumo(conn)
    for vt, (params, mass, vc) in types.items():
        rows = np.array(got[vt][:len(sched)])
        assert len(rows) == len(sched) and np.all(rows[:, 1] == 0.0)
        v = rows[:, 0]
        np.testing.assert_allclose(v, sched)
        v_prev = np.concatenate([[10.0], v[:-1]])
        eq, _ = _one(params, None if mass is None else float(mass))
        z = np.zeros_like(v)
        x = Inputs(v=v, a=v - v_prev, theta=z, wind=z, mass=z + 1.0, rho=z + 1.2041,
                   v_acc=(v + v_prev) / 2)
        ours = eq.chain.evaluate(eq.power(x), v)["power_w"]
        np.testing.assert_allclose(ours, rows[:, 2], rtol=1e-9, err_msg=vt)
    model = _one(types["cd"][0])[0].chain.provenance["sumo_energy_model"]
    assert {k for k, d in model.items() if d["from"] == "SUMO default"} == {
        "mass", "frontSurfaceArea", "rotatingMass", "radialDragCoefficient", "rollDragCoefficient",
        "constantPowerIntake", "propulsionEfficiency", "recuperationEfficiency",
        "recuperationEfficiencyByDeceleration"}
