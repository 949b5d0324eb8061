"""SUMO's MMPEVEM (``emissionClass="MMPEVEM"``; Koch, Badalian et al., "Accurate
physics-based modeling of electric vehicle energy consumption in the SUMO traffic
microsimulator", ITSC 2021, DOI 10.1109/ITSC48978.2021.9564463; src/utils/emissions/
HelpersMMPEVEM.cpp and CharacteristicMap.cpp) as a road-load equation and a battery chain
whose motor, inverter and battery are SUMO's.

Per step, with v̄ = v − a·Δt/2 the step's mean speed (MMPEVEM evaluates every force there)
and F the tractive force at the wheels::

    F      = m·e_i·a + m·g·sin θ + c_rr·m·g·cos θ + ½·1.204·c_d·A·v̄²     e_i = 1 + Θ/(m·r²)
    n      = v̄·60·i/(2π·r) [rpm], ω = 2π·n/60 (1e-6 where 0)
    M      = F·r/i / η_gear (F ≥ 0), F·r/i · η_gear (F < 0)             motor torque [N·m]
    P_m    = M·ω, capped: M ≤ M_max, P_m ≤ P_max (traction; SUMO then writes nan),
             M ≥ −M_rec, P_m ≥ −P_rec (recuperation: the rest goes to the friction brakes)
    P_loss = the power-loss map of motor and inverter at (n, M) (outside it SUMO writes nan)
    P_b    = P_m + P_loss + P_const
    P_bat  = U²/(2R) − U·sqrt((U² − 4R·P_b)/(4R²))                      (battery losses R·I²)

The road load is the equation's terms (:func:`mmpevem_equation`): acc e_i, grade
g_SUMO/G, roll c_rr·g_SUMO/G (``roll`` carries cos θ), aero ½·1.204·c_d·A. The chain
(:class:`SumoMotor`, an :class:`~sumo_drvpw.model.chain.EnergyChain`'s ``motor``) gets that
driving power P = F·v̄ and v̄, so F = P/v̄; standing (v̄ = 0), where P is 0, the motor still
holds the car on a slope: F = m·(e_i·a + g·sin θ) from the signals ``accel_mps2`` and
``grade_rad`` (0 when not given), as SUMO books it. Riding persons (signal ``load_kg``, L;
SUMO's getTotalMass) add to the mass but not to the rotating inertia: F = P/v̄ − (e_i − 1)·L·a
(P from the terms at m + L), standing F = (m + L)·(a + g·sin θ) + (e_i − 1)·m·a. The SUMO
loop evaluates an equation with such a chain at the step's mean speed (:mod:`sumo_drvpw.sim.ledger`).

Its battery power splits as: auxiliary = P_const; traction = max(P_bat − P_const, 0);
recuperated = min(P_bat − P_const, 0); friction brakes = the recuperation beyond the caps
(at the motor shaft).

Where SUMO 1.28 writes nan (a traction torque or power beyond the motor's limits, or an
operating point outside the loss map, e.g. SUMO's i3 above 150 km/h), this books the capped
state the model describes, with the loss at the map's nearest edge (an undefined point of
the map, nan in it: no loss).

SUMO 1.28's values of a parameter a vType leaves out (:data:`SUMO_DEFAULTS`) are those of
its shipped ``data/emissions/MMPEVEM/VW_ID3.xml`` with a loss map of 0 W everywhere;
``vehicleMass`` is not read (the ``mass`` attribute, else 1794 kg, plus ``loading``).
Probed with emissionsDrivingCycle of SUMO 1.28.0 on 2026-11-27 (a vType with no params,
one with two, the shipped BMW i3: every step within 5e-5 Wh, nan on the same steps;
tests/test_mmpevem.py repeats it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.constants import G, G_UNIT

#: MMPEVEM's fixed air density (HelpersMMPEVEM.cpp RHO_AIR) [kg/m³]
RHO_MMPEVEM = 1.204
#: its speed below which the motor stands (EPS) [m/s] and ω is 1e-6
EPS = 1e-6
#: a loss map of 0 W everywhere (SUMO's default)
ZERO_MAP = "2,1|-1e9,1e9;-1e9,1e9|0,0,0,0"
#: SUMO 1.28's value of each MMPEVEM parameter a vType leaves out (module docstring)
SUMO_DEFAULTS = {
    "mass": 1794.0, "wheelRadius": 0.3588, "internalMomentOfInertia": 12.5,
    "rollDragCoefficient": 0.007, "airDragCoefficient": 0.26, "frontSurfaceArea": 2.36,
    "gearRatio": 10.0, "gearEfficiency": 0.96, "maximumTorque": 310.0, "maximumPower": 107000.0,
    "maximumRecuperationTorque": 95.5, "maximumRecuperationPower": 42800.0,
    "internalBatteryResistance": 0.1142, "nominalBatteryVoltage": 396.0, "constantPowerIntake": 360.0,
}
#: the vType params MMPEVEM reads (besides the ``mass`` attribute and ``loading``)
MMPEVEM_PARAMS = tuple(k for k in SUMO_DEFAULTS if k != "mass") + ("powerLossMap",)
_POSITIVE = ("wheelRadius", "gearRatio", "gearEfficiency", "internalBatteryResistance",
             "nominalBatteryVoltage")


def is_mmpevem_class(ec: str | None) -> bool:
    """Whether an emissionClass names SUMO's MMPEVEM (``MMPEVEM`` or ``MMPEVEM/…``)."""
    return bool(ec) and (ec == "MMPEVEM" or ec.startswith("MMPEVEM/"))


@dataclass(frozen=True, eq=False)
class LossMap:
    """SUMO's 2-D characteristic map (CharacteristicMap.cpp): axes motor speed [rpm] and
    torque [N·m], values the power loss [W] (shape (len(torque), len(speed))).

    Evaluated as SUMO does: the nearest grid point, plus along each axis the slope to its
    neighbour on the point's side (no cross term: not bilinear); nan outside the axes."""

    text: str
    speed_rpm: np.ndarray
    torque_nm: np.ndarray
    loss_w: np.ndarray

    @classmethod
    def parse(cls, text: str, where: str = "powerLossMap") -> "LossMap":
        try:
            dims, axes, vals = str(text).strip().split("|")
            if [int(d) for d in dims.split(",")] != [2, 1]:
                raise ValueError("a map of motor speed and torque to one loss: dimensions 2,1")
            ax = [np.array([float(x) for x in a.split(",")]) for a in axes.split(";")]
            y = np.array([float(x) for x in vals.split(",")])
            if len(ax) != 2:
                raise ValueError("two axes separated by ';'")
            if y.size != ax[0].size * ax[1].size:
                raise ValueError(f"{y.size} values for {ax[0].size} × {ax[1].size} grid points")
            if any(a.size < 1 or np.any(np.diff(a) <= 0) for a in ax):
                raise ValueError("each axis must rise strictly")
            if not all(np.isfinite(a).all() for a in ax) or np.isinf(y).any():
                raise ValueError("axes must be finite, values finite or nan (an undefined point)")
        except ValueError as e:
            raise UserError(f"{where}: not a power-loss map 'dims|speed axis;torque axis|values' ({e})") from None
        return cls(str(text).strip(), ax[0], ax[1], y.reshape(ax[1].size, ax[0].size))

    def __call__(self, n_rpm, m_nm) -> np.ndarray:
        pts = [np.atleast_1d(np.asarray(n_rpm, float)), np.atleast_1d(np.asarray(m_nm, float))]
        if pts[0].shape != pts[1].shape:  # (a step's speeds and torques: no views to build)
            pts = np.broadcast_arrays(*pts)
        axes = (self.speed_rpm, self.torque_nm)
        idx, ok = [], np.ones(pts[0].shape, bool)
        for ax, x in zip(axes, pts):
            last = ax.size - 1
            k = np.searchsorted(ax, x, side="right") - 1  # ax[k] <= x < ax[k + 1]
            inside = (k >= 0) & (k < last)
            k = np.clip(k, 0, max(last - 1, 0))
            k1 = np.minimum(k + 1, last)
            low = (ax[0] - EPS <= x) & (x < ax[0])
            high = (ax[last] <= x) & (x < ax[last] + EPS)
            j = np.where(low, 0, np.where(high, last, np.where(x - ax[k] <= ax[k1] - x, k, k1)))
            ok &= low | high | inside
            idx.append(j)
        at = lambda jn, jm: self.loss_w[jm, jn]  # noqa: E731
        y_nn = at(idx[0], idx[1])
        y = y_nn.copy()
        for i, (ax, x) in enumerate(zip(axes, pts)):
            last = ax.size - 1
            j = idx[i]
            s = x - ax[j]
            back = ((s < 0) & (j > 0)) | ((s >= 0) & (j == last) & (j > 0))
            fwd = ~back & (((s < 0) & (j == 0) & (j < last)) | ((s >= 0) & (j < last)))
            an = np.where(back, j - 1, np.where(fwd, j + 1, j))
            nb = [idx[0], idx[1]]
            nb[i] = an
            y_an = at(nb[0], nb[1])
            dx = np.where(back, ax[j] - ax[an], ax[an] - ax[j])
            dy = np.where(back, y_nn - y_an, y_an - y_nn)
            use = (np.abs(s) > EPS) & (back | fwd)
            y = y + np.where(use, s * dy / np.where(use, dx, 1.0), 0.0)
        return np.where(ok, y, np.nan)


def _shaped(x, shape, scalar: bool = True) -> np.ndarray:
    """``x`` as a float array of ``shape``: as it is where it has that shape (or, ``scalar``,
    is one number, which NumPy's operations broadcast), else a broadcast view."""
    x = np.asarray(x, float)
    return x if x.shape == shape or (scalar and x.ndim == 0) else np.broadcast_to(x, shape)


@dataclass(frozen=True, eq=False)
class SumoMotor:
    """MMPEVEM's motor, gear, inverter and battery (module docstring; SI units, speeds of
    the motor in rpm only on the loss map)."""

    mass_kg: float
    mass_factor: float
    wheel_radius_m: float
    gear_ratio: float
    gear_efficiency: float
    max_torque_nm: float
    max_power_w: float
    max_recuperation_torque_nm: float
    max_recuperation_power_w: float
    battery_resistance_ohm: float
    battery_voltage_v: float
    aux_power_w: float
    loss_map: LossMap

    def battery(self, p_drive_w, v_mps, signals: Mapping | None = None, aux_w=None) -> dict:
        """Battery power [W] and its parts (:meth:`EnergyChain.evaluate`'s keys) plus
        ``invalid`` (bool: where SUMO writes nan) from driving power P [W] at the mean speed
        v̄ [m/s] of each step. ``aux_w``: the auxiliary power drawn at the battery, P_const
        (default :attr:`aux_power_w`; an :class:`EnergyChain` passes its own, loads, HVAC and
        standstill draw included)."""
        p = np.asarray(p_drive_w, float)
        # (a step's arrays have the samples' shape and a missing signal is one number: no
        # broadcast view is built for them — elementwise the same operations, bit for bit)
        aux = _shaped(self.aux_power_w if aux_w is None else aux_w, p.shape)
        v = _shaped(v_mps, p.shape, scalar=False)
        sig = signals or {}
        a = np.nan_to_num(_shaped(sig.get("accel_mps2", 0.0), p.shape))
        th = np.nan_to_num(_shaped(sig.get("grade_rad", 0.0), p.shape))
        load = np.nan_to_num(_shaped(sig.get("load_kg", 0.0), p.shape))
        moving = np.abs(v) > EPS
        # riders (load L) add to m but not to Θ/r²: m·e_i becomes m + L + (e_i − 1)·m, while P was
        # evaluated with e_i·(m + L) (the equation's fixed acc coefficient)
        inertia = (self.mass_factor - 1.0) * self.mass_kg
        hold = (self.mass_kg + load) * (a + G_UNIT * np.sin(th)) + inertia * a
        f = np.where(moving, p / np.where(moving, v, 1.0) - (self.mass_factor - 1.0) * load * a, hold)
        r, i, eta = self.wheel_radius_m, self.gear_ratio, self.gear_efficiency
        n = v / (2.0 * math.pi * r) * 60.0 * i
        w = 2.0 * math.pi * n / 60.0
        w = np.where(w == 0.0, EPS, w)
        m = f * r / i
        m = np.where(f < 0, m * eta, m / eta)
        pm = m * w
        raw = pm
        trac = m >= 0
        over = trac & (m > self.max_torque_nm)
        m = np.where(over, self.max_torque_nm, m)
        pm = np.where(over, m * w, pm)
        bad = over.copy()
        over = trac & (pm > self.max_power_w)
        pm = np.where(over, self.max_power_w, pm)
        m = np.where(over, pm / w, m)
        bad |= over
        rec = ~trac
        over = rec & (m < -self.max_recuperation_torque_nm)
        m = np.where(over, -self.max_recuperation_torque_nm, m)
        pm = np.where(over, m * w, pm)
        over = rec & (pm < -self.max_recuperation_power_w)
        pm = np.where(over, -self.max_recuperation_power_w, pm)
        m = np.where(over, pm / w, m)
        loss = self.loss_map(n, m).reshape(p.shape)
        off = ~np.isfinite(loss)
        if off.any():  # off the map (SUMO: nan): the loss at its nearest edge; an undefined point: 0
            lm = self.loss_map
            edge = lm(np.clip(n, lm.speed_rpm[0], lm.speed_rpm[-1]), np.clip(m, lm.torque_nm[0], lm.torque_nm[-1]))
            loss = np.where(off, edge.reshape(p.shape), loss)
        bad |= off
        pb = pm + np.nan_to_num(loss, nan=0.0) + aux
        u, res = self.battery_voltage_v, self.battery_resistance_ohm
        disc = u * u - 4.0 * res * pb
        bad |= disc < 0  # beyond what the battery can deliver: SUMO's square root is nan
        total = u * u / (2.0 * res) - u * np.sqrt(np.maximum(disc, 0.0) / (4.0 * res * res))
        drive = total - aux
        return {"traction_w": np.maximum(drive, 0.0), "recuperated_w": np.minimum(drive, 0.0),
                "auxiliary_w": np.array(aux, float) if aux.shape == p.shape else np.full(p.shape, aux),
                "friction_brake_w": np.where(rec, np.minimum(raw - pm, 0.0), 0.0),
                "power_w": total, "invalid": bad}

    def to_dict(self) -> dict:
        """The ``[chain.motor]`` table."""
        d = {k: float(getattr(self, k)) for k in _FIELDS}
        d["loss_map"] = self.loss_map.text
        return d


_FIELDS = ("mass_kg", "mass_factor", "wheel_radius_m", "gear_ratio", "gear_efficiency", "max_torque_nm",
           "max_power_w", "max_recuperation_torque_nm", "max_recuperation_power_w",
           "battery_resistance_ohm", "battery_voltage_v", "aux_power_w")


#: [chain] keys a motor replaces (its loss map, limits and battery)
_REPLACED = ("traction_efficiency", "recuperation_efficiency", "recuperation_limit_w", "recuperation_by_decel_mps2")


def motor_from_dict(chain_doc: dict, where: str) -> SumoMotor:
    """A :class:`SumoMotor` from the ``[chain.motor]`` table of a ``[chain]`` table; errors
    name ``where`` and the key (also a key of the chain the motor replaces)."""
    predicts = chain_doc.get("predicts", "battery")
    if predicts != "battery":
        raise UserError(f"{where} [chain.motor]: SUMO's MMPEVEM motor predicts the battery, got predicts = {predicts!r}")
    both = [k for k in _REPLACED if k in chain_doc]
    if both:
        raise UserError(f"{where} [chain]: '{both[0]}' with [chain.motor]: the motor's loss map, limits and "
                        "battery take its place; leave it out")
    doc = chain_doc["motor"]
    if not isinstance(doc, dict):
        raise UserError(f"{where} [chain.motor]: must be a table")
    bad = sorted(set(doc) - set(_FIELDS) - {"loss_map"})
    missing = [k for k in _FIELDS + ("loss_map",) if k not in doc]
    if bad or missing:
        raise UserError(f"{where} [chain.motor]: " + (f"unknown key(s) {bad}" if bad else f"missing {missing}")
                        + f" (keys: {', '.join(_FIELDS)}, loss_map)")
    if "aux_power_w" in chain_doc and "aux_power_w" in doc and chain_doc["aux_power_w"] != doc["aux_power_w"]:
        raise UserError(f"{where} [chain] aux_power_w = {chain_doc['aux_power_w']!r} and [chain.motor] aux_power_w = "
                        f"{doc['aux_power_w']!r}: the motor's constant power intake is the chain's; give one value")
    kw = {}
    for k in _FIELDS:
        try:
            x = float(doc[k])
        except (TypeError, ValueError):
            raise UserError(f"{where} [chain.motor] {k}: must be a number, got {doc[k]!r}") from None
        positive = k not in ("aux_power_w",) and not k.startswith("max_")  # limits and intake may be 0
        if not math.isfinite(x) or x < 0 or (x == 0 and positive) or (k == "gear_efficiency" and x > 1):
            raise UserError(f"{where} [chain.motor] {k}: must be a finite number " + ("> 0" if positive else "≥ 0")
                            + (" and ≤ 1" if k == "gear_efficiency" else "") + f", got {doc[k]!r}")
        kw[k] = x
    return SumoMotor(**kw, loss_map=LossMap.parse(doc["loss_map"], f"{where} [chain.motor] loss_map"))


def mmpevem_values(params: Mapping, mass_kg: float | None, where: str) -> dict[str, tuple]:
    """MMPEVEM's values of one vType: {parameter: (value, "given" or "SUMO default")} for
    mass, loading, every key of :data:`SUMO_DEFAULTS` and powerLossMap (text)."""
    out: dict[str, tuple] = {}
    if mass_kg is not None:
        if not (math.isfinite(float(mass_kg)) and float(mass_kg) > 0):
            raise UserError(f"{where}: mass must be a positive number, got {mass_kg!r}")
        out["mass"] = (float(mass_kg), "given")
    else:
        out["mass"] = (SUMO_DEFAULTS["mass"], "SUMO default")
    for k in ("loading",) + tuple(SUMO_DEFAULTS)[1:]:
        raw = params.get(k)
        if raw is None:
            out[k] = (0.0, "none") if k == "loading" else (SUMO_DEFAULTS[k], "SUMO default")
            continue
        try:
            x = float(raw)
        except (TypeError, ValueError):
            raise UserError(f"{where}: param {k} is not a number: {raw!r}") from None
        if not math.isfinite(x) or x < 0 or (k in _POSITIVE and x == 0):
            raise UserError(f"{where}: param {k} must be a finite number "
                            + ("> 0" if k in _POSITIVE else "≥ 0") + f", got {raw!r}")
        if k == "gearEfficiency" and x > 1:
            raise UserError(f"{where}: param gearEfficiency must lie in (0, 1], got {raw!r}")
        out[k] = (x, "given")
    text = params.get("powerLossMap")
    out["powerLossMap"] = (str(text), "given") if text is not None else (ZERO_MAP, "SUMO default")
    return out


def mmpevem_equation(name: str, params: Mapping, mass_kg: float | None = None, where: str = "vType",
                     vclasses=("passenger",), source: str = ""):
    """One vType's MMPEVEM parameters as an :class:`~sumo_drvpw.model.equations.Equation`
    (its road load) with a battery chain holding SUMO's motor (:class:`SumoMotor`); returns
    (equation, notes on what it cannot express)."""
    from sumo_drvpw.model.chain import EnergyChain
    from sumo_drvpw.model.equations import Equation

    val = mmpevem_values(params, mass_kg, where)
    f = {k: v for k, (v, _) in val.items()}
    m = f["mass"] + f["loading"]
    e_i = 1.0 + f["internalMomentOfInertia"] / (m * f["wheelRadius"] ** 2)
    terms = {"acc": e_i, "grade": G_UNIT / G}
    if f["rollDragCoefficient"]:
        terms["roll"] = f["rollDragCoefficient"] * G_UNIT / G
    cda = f["airDragCoefficient"] * f["frontSurfaceArea"]
    if cda:
        terms["aero"] = 0.5 * RHO_MMPEVEM * cda
    motor = SumoMotor(
        mass_kg=m, mass_factor=e_i, wheel_radius_m=f["wheelRadius"], gear_ratio=f["gearRatio"],
        gear_efficiency=f["gearEfficiency"], max_torque_nm=f["maximumTorque"], max_power_w=f["maximumPower"],
        max_recuperation_torque_nm=f["maximumRecuperationTorque"],
        max_recuperation_power_w=f["maximumRecuperationPower"],
        battery_resistance_ohm=f["internalBatteryResistance"], battery_voltage_v=f["nominalBatteryVoltage"],
        aux_power_w=f["constantPowerIntake"],
        loss_map=LossMap.parse(f["powerLossMap"], f"{where}: param powerLossMap"))
    # the loss map: its text in the chain; here 0.0 for SUMO's default (0 W everywhere)
    prov = {k: {"value": v if k != "powerLossMap" else (0.0 if s == "SUMO default" else "given"), "from": s}
            for k, (v, s) in val.items()}
    chain = EnergyChain(predicts="battery", aux_power_w=f["constantPowerIntake"], motor=motor,
                        provenance={"sumo_mmpevem": prov})
    notes = ["steps where SUMO writes nan (a demand beyond the motor's torque or power, or off the loss map): "
             "booked at the motor's limits, with the loss at the map's nearest edge"]
    if params.get("vehicleMass") is not None:
        notes.append("vehicleMass: SUMO 1.28's MMPEVEM does not read it either (the mass attribute, else 1794 kg)")
    defaults = sorted(k for k, (_, s) in val.items() if s == "SUMO default")
    desc = (f"SUMO MMPEVEM parameters of {where} (HelpersMMPEVEM.cpp: road load as terms at the step's mean "
            "speed, motor, loss map and battery as the chain's motor; SUMO 1.28 defaults for "
            + (", ".join(defaults) or "none") + ")")
    eq = Equation(name=name, terms=terms, mass_kg=m, description=desc, source=source or where,
                  chain=chain, vclasses=tuple(vclasses))
    return eq, notes


def evaluate_where(chain, sel: np.ndarray, p_drive_w, v_mps, dt_s, signals: Mapping | None, keys=None,
                   **state) -> dict:
    """``chain.evaluate`` on the vehicles ``sel`` only (zeros elsewhere): SUMO's motor costs
    about 1 µs per vehicle and step, and a run's MMPEVEM equation books one vType. ``state``:
    each vehicle's hybrid battery (``stored_j``, ``spent_j``: model/chain_buffer.py, chain_plugin.py).
    ``keys``: the outputs the caller reads (None: all; where only some vehicles are selected,
    the others are not spread back to every vehicle)."""
    n = len(sel)
    if sel.all():
        return chain.evaluate(p_drive_w, v_mps, dt_s, signals, **state)
    idx = np.flatnonzero(sel)  # (one search of the mask, not one per input)

    def take(x):  # a per-vehicle input's selected rows; a number, or another shape, as it is
        if type(x) is not np.ndarray:  # (np.ndim, np.shape: slow wrappers, on a step's arrays)
            return x if isinstance(x, (float, int)) else (np.asarray(x)[idx] if np.ndim(x) and np.shape(x)[0] == n else x)
        return x[idx] if x.ndim and x.shape[0] == n else x

    sub = chain.evaluate(take(p_drive_w), take(v_mps), take(dt_s), {k: take(x) for k, x in (signals or {}).items()},
                         **{k: take(x) for k, x in state.items()})
    out = {}
    for k, x in sub.items():
        if keys is not None and k not in keys:
            continue
        full = np.zeros(n, dtype=np.asarray(x).dtype)
        full[idx] = x
        out[k] = full
    return out


def mmpevem_params(eq, frontal_area_m2: float | None = None) -> tuple[dict, list[str]]:
    """The inverse of :func:`mmpevem_equation`: an equation whose chain is SUMO's motor as
    MMPEVEM vType values ({"mass": kg, param: value}, the loss map's text included), and
    what MMPEVEM cannot express of it (terms other than its road load, or coefficients that
    are not the motor's; the chain's loads, HVAC, standstill draw), with why. ``frontal_area_m2``
    splits c_d·A (default 1 m²)."""
    mo = eq.chain.motor
    m, r = mo.mass_kg, mo.wheel_radius_m
    k = G / G_UNIT  # the terms carry SUMO's g as a share of the project's
    want = {"acc": mo.mass_factor, "grade": 1.0 / k}
    missing: list[str] = []
    if eq.mass_kg is not None and abs(eq.mass_kg - m) > 1e-9 * m:
        missing.append(f"the equation's mass {eq.mass_kg:g} kg: MMPEVEM's is the motor's {m:g} kg")
    for t, c in eq.terms.items():
        if t in want and abs(c - want[t]) > 1e-9 * abs(want[t]):
            missing.append(f"{t} coefficient {c:g} (MMPEVEM's is {want[t]:g} for this motor)")
        elif t not in want and t not in ("roll", "aero_rho", "aero"):
            missing.append(f"{t} (MMPEVEM's road load has acc, grade, roll and aero only)")
    area = float(frontal_area_m2) if frontal_area_m2 else 1.0
    cda = eq.terms.get("aero", 0.0) / (0.5 * RHO_MMPEVEM) + eq.terms.get("aero_rho", 0.0)
    ch = eq.chain
    for what, has in (("logged loads", ch.loads), ("an HVAC", ch.hvac), ("a standstill draw", ch.standstill_aux_w)):
        if has:
            missing.append(f"the chain's {what} (MMPEVEM draws constantPowerIntake only)")
    p = {"mass": m, "wheelRadius": r, "internalMomentOfInertia": (mo.mass_factor - 1.0) * m * r * r,
         "rollDragCoefficient": eq.terms.get("roll", 0.0) * k, "airDragCoefficient": cda / area,
         "frontSurfaceArea": area, "gearRatio": mo.gear_ratio, "gearEfficiency": mo.gear_efficiency,
         "maximumTorque": mo.max_torque_nm, "maximumPower": mo.max_power_w,
         "maximumRecuperationTorque": mo.max_recuperation_torque_nm,
         "maximumRecuperationPower": mo.max_recuperation_power_w,
         "internalBatteryResistance": mo.battery_resistance_ohm,
         "nominalBatteryVoltage": mo.battery_voltage_v, "constantPowerIntake": ch.aux_power_w,
         "powerLossMap": mo.loss_map.text}
    return p, missing
