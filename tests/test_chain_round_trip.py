"""A charge-sustaining hybrid's braking energy given back in a fuel chain (model/chain.py
``recuperation_round_trip``, ``recuperation_limit_w``): only for such a hybrid, in [0, 1],
kept through the file, credited at the margin while braking (by hand), and refused by a
fuel calibration that would drop it (fit/chain.declared_fuel_cut)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.chain_toml import chain_from_dict

DOC = {"predicts": "fuel", "fuel": "diesel", "marginal_efficiency": 0.45, "idle_fuel_power_w": 1000.0,
       "engine_off_below_w": 100.0, "charge_sustaining": True, "recuperation_round_trip": 0.7,
       "recuperation_limit_w": 50000.0}


@pytest.mark.parametrize("doc, says", [
    ({"predicts": "fuel", "recuperation_round_trip": 0.7}, "charge_sustaining = true"),
    ({"predicts": "fuel", "charge_sustaining": True, "recuperation_round_trip": 1.2}, "in [0, 1]"),
    ({"predicts": "fuel", "charge_sustaining": True, "recuperation_round_trip": -0.1}, "must be ≥ 0"),
])
def test_a_round_trip_outside_a_charge_sustaining_hybrid_is_refused(doc, says):
    with pytest.raises(UserError, match="recuperation_round_trip") as e:
        chain_from_dict(doc, "x.toml")
    assert says in str(e.value) and "x.toml" in str(e.value)


def test_a_round_trip_survives_the_file():
    ch = chain_from_dict(DOC)
    assert chain_from_dict(ch.to_dict()) == ch
    no = chain_from_dict({k: x for k, x in DOC.items() if k != "recuperation_round_trip"})
    p, v = np.array([-80000.0]), np.array([5.0])
    assert no.evaluate(p, v)["power_w"][0] == 0.0   # no round trip, no credit (the limit alone: nothing)
    assert ch.evaluate(p, v)["power_w"][0] == pytest.approx(-0.7 * 50000 / 0.45)


def test_a_calibration_refuses_a_declared_round_trip_it_would_drop():
    """A fuel chain's calibration (in memory and streamed: fit/chain.declared_fuel_cut) keeps a
    declared overrun cut-off and fits η_m, P_idle; a declared round trip it cannot keep is
    refused with the file's name, not dropped without a word."""
    from sumo_drvpw.fit.chain import declared_fuel_cut

    doc = {**DOC, "fuel_cut_below_w": 0.0}
    assert declared_fuel_cut(SimpleNamespace(chain=chain_from_dict(
        {k: x for k, x in doc.items() if k != "recuperation_round_trip"}))) == 0.0
    assert declared_fuel_cut(None) is None
    with pytest.raises(UserError, match="recuperation_round_trip") as e:
        declared_fuel_cut(SimpleNamespace(chain=chain_from_dict(doc, "bus.toml")))
    assert "bus.toml" in str(e.value)



def test_the_closed_loop_s_slope_holds_the_braking_credit():
    """fit/chain_linear.gains (diagnose and the closed loop on a fuel target linearise the
    chain with it) gave a fuel chain no slope where it brakes, so a hybrid that gives its
    braking energy back read as if braking cost nothing either way: the chain's own change
    per W of driving power there is η_rt/(η_t·η_m) (0.7/0.45 here), up to the motor's limit."""
    from sumo_drvpw.fit.chain_linear import gains

    ch = chain_from_dict({**DOC, "traction_efficiency": 0.85, "aux_power_w": 2000.0})
    p = np.array([-80000.0, -30000.0, -100.0, 20000.0, 60000.0])
    v = np.full(p.size, 8.0)
    gw, _ = gains(ch, p, v)
    num = (ch.evaluate(p + 1.0, v)["power_w"] - ch.evaluate(p - 1.0, v)["power_w"]) / 2.0
    np.testing.assert_allclose(gw, num, rtol=1e-9)
    assert gw[1] == pytest.approx(0.7 / 0.85 / 0.45) and gw[0] == 0.0  # beyond the 50-kW limit: none
