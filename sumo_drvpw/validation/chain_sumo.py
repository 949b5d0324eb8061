"""SUMO's own energy models on the shared real trips, beside the energy chain (issue #12 §5).

Each trip is driven through ``emissionsDrivingCycle`` (SUMO's tool that runs one emission
model along a time line): the trip averaged to 1 s (speed, grade; seconds without a
sample interpolated linearly, as the tool books each line as one second), acceleration
v(t) − v(t−1) per second, slope in degrees. Models:

* electric (battery energy, the tool's ``electricity`` column [Wh per step]):
  SUMO's Energy model (``Energy/unknown``, HelpersEnergy) and MMPEVEM (Koch et al., ITSC
  2021, with its shipped ``BMW_i3.xml``), each once with SUMO's shipped defaults and once
  with the parameters the calibrated road-load equation and energy chain produced
  (:func:`chain_vtype_params`);
* fuel (the tool's ``fuel`` column [mg per step]): a PHEMlight5 class (the Prius Gen 2 is a
  Euro-4 petrol car: ``PHEMlight5/PC_EU4_G``, the only petrol passenger-car class SUMO 1.28
  ships in PHEMlight5; SUMO ships no hybrid class).

Steps a model returns NaN for (beyond its power map) are left out and counted.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

#: electric models side by side: label → (emission class, shipped vType file under SUMO_HOME
#: or None, its vType id, overridden by the chain's parameters?)
ELECTRIC_MODELS = {
    "sumo_mmpevem_i3": ("MMPEVEM", "data/emissions/MMPEVEM/BMW_i3.xml", "BMW_i3", False),
    "sumo_mmpevem_chain": ("MMPEVEM", "data/emissions/MMPEVEM/BMW_i3.xml", "BMW_i3", True),
    "sumo_energy_default": ("Energy/unknown", None, None, False),
    "sumo_energy_chain": ("Energy/unknown", None, None, True),
}
#: fuel models: label → emission class (PHEMlight5 needs its data path)
FUEL_MODELS = {"sumo_phemlight5_pc_eu4_g": "PHEMlight5/PC_EU4_G"}
#: vType parameters an electric model takes from the chain (the rest stay shipped)
CHAIN_KEYS = {"Energy/unknown": ("mass", "frontSurfaceArea", "airDragCoefficient", "rollDragCoefficient",
                                 "rotatingMass", "constantPowerIntake", "radialDragCoefficient",
                                 "propulsionEfficiency", "recuperationEfficiency"),
              # MMPEVEM computes its losses from its motor map, gear efficiency and battery
              # resistance; it takes the road load, the auxiliary power and the limit
              "MMPEVEM": ("mass", "frontSurfaceArea", "airDragCoefficient", "rollDragCoefficient",
                          "constantPowerIntake", "maximumRecuperationPower", "gearEfficiency")}


def sumo_tool(name: str) -> str | None:
    """Path of a SUMO executable beside this Python's, else on PATH, else None."""
    exe = Path(sys.executable).parent / name
    return str(exe) if exe.is_file() else shutil.which(name)


def sumo_home() -> Path | None:
    try:
        import sumo as _sumo
    except ImportError:
        return None
    return Path(_sumo.SUMO_HOME)


def chain_vtype_params(eq, chain, mass_kg: float, frontal_area_m2: float | None = None,
                       extra_aux_w: float = 0.0, at_motor_shaft: bool = False) -> tuple[dict, list[str]]:
    """vType parameters for SUMO's electric models from a road-load equation and its battery
    chain. The road load through the physical reading of its coefficients
    (:func:`sumo_drvpw.fit.physical.physical_reading` at SUMO's fixed ρ, so c·v³ keeps its
    watts): ``acc`` → rotatingMass = (c − 1)·m, ``aero`` → A·C_d, ``roll`` → rollDragCoefficient
    (the same mapping as :mod:`sumo_drvpw.sim.export`); the chain: ``propulsionEfficiency`` = η_t,
    ``recuperationEfficiency`` = η_r, ``constantPowerIntake`` = P_aux,0 + ``extra_aux_w`` [W]
    (e.g. a trip's mean logged heater and A/C load, which SUMO has no signal for),
    ``maximumRecuperationPower`` = the recuperation limit; with ``at_motor_shaft`` (the equation
    was calibrated on motor torque × speed, so it includes the gear's losses) MMPEVEM's
    ``gearEfficiency`` = 1, so they are not counted twice.

    Parameters
    ----------
    eq : road-load equation (terms acc, grade, aero or aero_rho, roll; others are listed)
    chain : its battery :class:`~sumo_drvpw.model.chain.EnergyChain`
    mass_kg : vehicle mass [kg]
    frontal_area_m2 : frontal area to split A·C_d [m²] (default 1 m²)

    Returns ({parameter: value}, [what SUMO cannot express, with why])."""
    from sumo_drvpw.fit.physical import physical_reading
    from sumo_drvpw.model.constants import RHO_DEFAULT
    from sumo_drvpw.model.chain_sumo import chain_energy_params

    m = float(mass_kg)
    reading = physical_reading(eq.terms, RHO_DEFAULT)
    cda = cr = rot = 0.0
    missing = []
    for t, r in reading.items():
        if t in ("aero", "aero_rho"):
            cda += r["value"]
        elif t == "roll":
            cr += r["value"]
        elif t == "acc":
            rot = max(0.0, (r["value"] - 1.0) * m)
        elif t == "grade":
            if abs(r["value"] - 1.0) > 1e-9:
                missing.append(f"grade coefficient {r['value']:.4g} (SUMO's grade term is m·g·v·sin θ, "
                               "coefficient 1)")
        else:
            missing.append(f"{t} (no counterpart in SUMO's models)")
    area = float(frontal_area_m2) if frontal_area_m2 else 1.0
    p = {"mass": m, "frontSurfaceArea": area, "airDragCoefficient": max(cda, 0.0) / area,
         "rollDragCoefficient": max(cr, 0.0), "rotatingMass": rot, "radialDragCoefficient": 0.0}
    # η_t, η_r and the constant auxiliary power as export-vtype maps them (one mapping)
    cp, cm = chain_energy_params(chain)
    missing += [m for m in cm if " is a table " in m]
    p.update(cp)
    p["constantPowerIntake"] += float(extra_aux_w)
    if chain.recuperation_limit_w is not None:
        p["maximumRecuperationPower"] = float(chain.recuperation_limit_w)
    if at_motor_shaft:
        p["gearEfficiency"] = 1.0
    return p, missing


def _vtype_file(path: Path, cls: str, vtype_id: str, base: Path | None, params: dict) -> None:
    """Write one vType: the shipped one (``base``) with ``params`` overriding its parameters,
    or a new one of ``cls``."""
    import xml.etree.ElementTree as ET

    if base is not None:
        root = ET.parse(base).getroot()
        vt = next(v for v in root.iter("vType") if v.get("id") == vtype_id)
    else:
        root = ET.Element("additional")
        vt = ET.SubElement(root, "vType", id=vtype_id, emissionClass=cls)
    for k, v in params.items():
        if k == "mass":
            vt.set("mass", f"{v:.9g}")
            continue
        for p in vt.findall("param"):
            if p.get("key") == k:
                vt.remove(p)
        ET.SubElement(vt, "param", key=k, value=f"{v:.9g}")
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)


def _timeline(t_s, v_mps, grade_rad, path: Path) -> None:
    import pandas as pd

    sec = np.floor(np.asarray(t_s, float) - float(t_s[0])).astype(int)
    df = pd.DataFrame({"s": sec, "v": v_mps, "g": np.nan_to_num(grade_rad)}).groupby("s").mean()
    # every second once (the tool books each line as one step): a log slower than 1 Hz or
    # with gaps is interpolated linearly in time
    df = df.reindex(np.arange(df.index.min(), df.index.max() + 1)).interpolate("index")
    v = df["v"].to_numpy()
    a = np.diff(v, prepend=v[0])
    pd.DataFrame({"t": df.index.to_numpy(float), "v": v, "a": a,
                  "slope": np.degrees(df["g"].to_numpy())}).to_csv(path, sep=";", header=False, index=False)


def _run(cmd: list[str], out: Path, column: int):
    import pandas as pd

    subprocess.run(cmd, check=True, capture_output=True)
    return pd.read_csv(out, sep=";", header=None).iloc[:, column].to_numpy(float)


def _kept_steps(t_s, n: int, drop) -> np.ndarray:
    """Which of the timeline's ``n`` 1-s steps to book: all, or those whose second holds no
    sample marked in ``drop`` (e.g. a logger dropout left out of the measured energy too)."""
    keep = np.ones(n, bool)
    if drop is not None and np.any(drop):
        t = np.asarray(t_s, float)
        sec = np.floor(t[np.asarray(drop, bool)] - float(t[0])).astype(int)
        keep[sec[(sec >= 0) & (sec < n)]] = False
    return keep


def sumo_battery_kwh(t_s, v_mps, grade_rad, workdir: Path, chain_params: dict | None = None,
                     drop=None) -> dict:
    """Battery energy [kWh] of one trip by SUMO's electric models (:data:`ELECTRIC_MODELS`);
    a model marked for the chain's parameters runs only when ``chain_params`` (from
    :func:`chain_vtype_params`) is given; the seconds holding a sample marked in ``drop``
    are not booked. Returns {label: {"kwh", "nan_steps"}}, or {} when SUMO's tools are not
    installed."""
    tool, home = sumo_tool("emissionsDrivingCycle"), sumo_home()
    if tool is None or home is None:
        return {}
    tl = workdir / "timeline.csv"
    _timeline(t_s, v_mps, grade_rad, tl)
    out = {}
    for label, (cls, vfile, vtype, use_chain) in ELECTRIC_MODELS.items():
        if use_chain and chain_params is None:
            continue
        o = workdir / f"{label}.csv"
        cmd = [tool, "-t", str(tl), "-e", cls, "--have-slope", "-o", str(o)]
        if use_chain:
            vt = workdir / f"{label}.xml"
            _vtype_file(vt, cls, vtype or "chain", home / vfile if vfile else None,
                        {k: v for k, v in chain_params.items() if k in CHAIN_KEYS[cls]})
            cmd += ["--additional-files", str(vt), "--vtype", vtype or "chain"]
        elif vfile:
            cmd += ["--additional-files", str(home / vfile), "--vtype", vtype]
        el = _run(cmd, o, -1)  # Wh per 1-s step
        el = el[_kept_steps(t_s, el.size, drop)]
        out[label] = {"kwh": float(np.nansum(el)) / 1000.0, "nan_steps": int(np.isnan(el).sum())}
    return out


def sumo_fuel_l(t_s, v_mps, grade_rad, workdir: Path, density_kg_per_l: float) -> dict:
    """Fuel [L] of one trip by SUMO's fuel models (:data:`FUEL_MODELS`); {} without SUMO.
    The tool's fuel column is mg per 1-s step; litres = mg·1e-6 / density."""
    tool, home = sumo_tool("emissionsDrivingCycle"), sumo_home()
    if tool is None or home is None:
        return {}
    tl = workdir / "timeline.csv"
    _timeline(t_s, v_mps, grade_rad, tl)
    out = {}
    for label, cls in FUEL_MODELS.items():
        o = workdir / f"{label}.csv"
        cmd = [tool, "-t", str(tl), "-e", cls, "--have-slope", "-o", str(o),
               "--phemlight-path", str(home / "data" / "emissions" / cls.split("/")[0])]
        mg = _run(cmd, o, 9)
        out[label] = {"l": float(np.nansum(mg)) * 1e-6 / density_kg_per_l,
                      "nan_steps": int(np.isnan(mg).sum())}
    return out

