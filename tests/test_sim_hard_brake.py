"""A step SUMO ends at a deceleration no brake reaches (its emergency braking: a rehearsal's
400-t train stopped at a red signal from 64 m/s within one step) sheds the vehicle's kinetic
energy in friction brakes: the wheels' books keep it, but no battery chain recuperates it.
Before, the battery chain recuperated it all — 226 kWh in one second, the train's trip
booked at −165 kWh net where SUMO's emission output booked +53.5 kWh (SUMO booked only the
auxiliary power on that step)."""

from __future__ import annotations

from pathlib import Path

import pytest

from sumo_drvpw.model.equations import load_equation
from sumo_drvpw.sim.fcd import process_fcd
from sumo_drvpw.sim.loop import IMPOSSIBLE_DECEL_MPS2

HW_NET = Path(__file__).resolve().parent.parent / "sumo_drvpw" / "sim" / "builtin" / "networks" / "highway.net.xml"


def _fcd(path: Path, stop_from: float, steps_to_stop: int) -> Path:
    """A car at 30 m/s on the highway's first edge, then braking to a standstill at
    ``stop_from`` m/s over ``steps_to_stop`` 1-s steps, then standing."""
    rows, pos = [], 10.0
    speeds = [30.0] * 10 + [stop_from * (1 - k / steps_to_stop) for k in range(1, steps_to_stop + 1)] + [0.0] * 5
    for t, v in enumerate(speeds):
        pos += v
        rows.append(f'<timestep time="{t:.2f}"><vehicle id="car" type="DEFAULT_VEHTYPE" speed="{v:.4f}" '
                    f'pos="{pos:.4f}" lane="e01_0" x="{pos:.4f}" y="-4.80" angle="90.00"/></timestep>')
    path.write_text("<fcd-export>\n" + "\n".join(rows) + "\n</fcd-export>\n", encoding="utf-8")
    return path


@pytest.mark.parametrize("steps_to_stop,hard", [(1, 1), (5, 0)], ids=["one-step", "five-steps"])
def test_a_stop_beyond_any_brake_is_not_recuperated(tmp_path, steps_to_stop, hard):
    eq = load_equation("bmw_i3_battery")
    res = process_fcd(_fcd(tmp_path / "fcd.xml", 30.0, steps_to_stop), net=HW_NET, equations=[eq],
                      figures=False, step_length=1.0)
    assert res.summary["hard_brakes"]["samples"] == hard
    assert (res.summary["hard_brakes"]["max_decel_mps2"] > IMPOSSIBLE_DECEL_MPS2) == bool(hard)
    v = res.vehicles.set_index("equation").loc[eq.name]
    kinetic = 0.5 * v.mass_kg * 30.0 ** 2
    assert v.recup_total_j < -0.9 * kinetic  # the wheels shed the kinetic energy either way
    ch = res.chain_vehicles().set_index("equation").loc[eq.name]
    rec_j = ch.recuperated_kwh * 3.6e6
    if hard:  # in friction brakes: the battery takes none of it back
        assert rec_j == 0.0
        assert any("decelerated beyond any brake" in w for w in res.summary["warnings"])
    else:  # braked at 6 m/s²: the chain recuperates
        assert rec_j < -0.3 * kinetic
        assert not any("beyond any brake" in w for w in res.summary["warnings"])
