"""A vType changed during a trip to one that other equations book (a calibrator turning a
petrol car into a diesel car; a script's setType): each equation that applied books its own
part of the trip. Before (a rehearsal on SUMO calibrators), vehicles.parquet had no row for
the second type's equations (their energy was in the edge and class tables only) and gave
the first ones the whole trip's distance and time; edges booked a segment's distance on the
equation that applied when the vehicle left the edge; the chain's vehicle table gave the
diesel litres 0 km and the petrol ones the whole trip; the trace wrote the old equations'
rows after the change. Now vehicle, edge and class totals agree per equation in energy and
distance, live and replayed."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.sim import run_scenario
from sumo_drvpw.sim.fcd import process_fcd
from test_fcd_vtype_change import calibrated

pytestmark = pytest.mark.sumo

PETROL, DIESEL = "epa_gasoline_car", "epa_diesel_car"


def _scenario(d: Path) -> Path:
    """Petrol cars that a calibrator on their second edge (mid-edge) turns into diesel cars."""
    return calibrated(d, 'vClass="passenger" emissionClass="HBEFA4/PC_petrol_Euro-6ab"',
                      'vClass="passenger" emissionClass="HBEFA4/PC_diesel_Euro-6ab"',
                      route="c00c10 c10c20 c20c30", pos=40.0, end=250.0)


def _check(res, out: Path | None = None):
    v, e, c = res.vehicles, res.edges, res.classes
    both = v[v.equation.isin([PETROL, DIESEL])]
    per = both.pivot(index="vehicle", columns="equation", values="distance_m").fillna(0.0)
    assert len(per) == 6 and set(per.columns) == {PETROL, DIESEL}
    assert (per > 0).all().all()  # each car drove under both
    # the two parts make the trip: the distance of an equation that applied throughout
    whole = v[~v.equation.isin([PETROL, DIESEL])].groupby("vehicle").distance_m.max()
    np.testing.assert_allclose(per.sum(axis=1).sort_index(), whole.sort_index(), rtol=1e-12)
    for eq in (PETROL, DIESEL, *set(v.equation) - {PETROL, DIESEL}):
        ve, ee = v[v.equation == eq], e[e.equation == eq]
        ce = c[(c.equation == eq) & (c.term == c.term.iloc[0])]
        for col in ("traction_total_j", "recup_total_j"):
            assert ve[col].sum() == pytest.approx(ee[col].sum(), rel=1e-9, abs=1e-6)
        assert ve.distance_m.sum() == pytest.approx(ee.distance_m.sum(), rel=1e-9)
        assert ve.distance_m.sum() == pytest.approx(ce.distance_m.sum(), rel=1e-9)
    ch = res.chain_vehicles()
    for eq in (PETROL, DIESEL):
        km = ch[ch.equation == eq].set_index("vehicle").distance_km.sort_index()
        np.testing.assert_allclose(km.to_numpy(), per[eq].sort_index().to_numpy() / 1000.0, rtol=1e-9)
        assert (ch[ch.equation == eq].fuel_l > 0).all()
    if out is not None:  # the trace books each step by the equations that applied then
        tr = pd.read_parquet(out / "trace.parquet")
        cols = [k for k in tr.columns if k.endswith("_w") and k != "total_w"] or ["total_w"]
        got = tr.groupby(["vehicle", "equation"]).size()
        assert {eq for _, eq in got.index} >= {PETROL, DIESEL}
        dt = 1.0
        for (veh, eq), g in tr[tr.equation.isin([PETROL, DIESEL])].groupby(["vehicle", "equation"]):
            assert g.speed_mps.sum() * dt == pytest.approx(per.loc[veh, eq], rel=1e-9)
        assert cols


@pytest.mark.parametrize("chunk_rows", [None, 97], ids=["whole", "streamed"])
def test_a_vtype_change_to_other_equations_books_each_its_part(tmp_path, chunk_rows):
    cfg = _scenario(tmp_path)
    live = run_scenario(cfg, tmp_path / "live", end=250, figures=False, trace=True,
                        options=["--fcd-output", str(tmp_path / "fcd.xml"), "--precision", "6"])
    assert 'type="second"' in (tmp_path / "fcd.xml").read_text(encoding="utf-8")
    _check(live, tmp_path / "live")
    rep = process_fcd(tmp_path / "fcd.xml", scenario=cfg, end=250, figures=False, chunk_rows=chunk_rows)
    _check(rep)
    a = live.vehicles.set_index(["vehicle", "equation"]).sort_index()
    b = rep.vehicles.set_index(["vehicle", "equation"]).sort_index()
    assert a.index.equals(b.index)
    np.testing.assert_allclose(b[["traction_total_j", "distance_m", "time_s"]].to_numpy(),
                               a[["traction_total_j", "distance_m", "time_s"]].to_numpy(), rtol=1e-6, atol=1e-6)
