"""A virtual test track: synthetic 8 Hz Prius3-like logs with a declared truth.

The driver follows the seed paper's analytical patterns (Pitanuwat et al., Part I,
Sec. 3): maximal acceleration and braking, cruise at speeds up to 160 km/h, coast-down,
constant acceleration and deceleration, naturalistic free driving and EV-mode maximum
power, on a closed circuit with slopes and a steady wind. The truth driving power is a
declared equation (default ``drvpw_prius3``, Table 3 Indt var. 1) plus process noise;
the powertrain signals (engine, MG1, MG2 speed and torque) come from the inverse of the
power-split model in :mod:`sumo_drvpw.data.powertrain`, and every logged signal carries
sensor noise. The truth is written to the Parquet schema metadata (``sumo_drvpw.truth``).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from typing import Callable

import numpy as np
import pandas as pd

from sumo_drvpw.model.air import air_density
from sumo_drvpw.model.constants import G, KMH, RPM
from sumo_drvpw.model.equations import Equation, load_equation
from sumo_drvpw.model.terms import Inputs
from sumo_drvpw.model.vehicles import Vehicle, load_vehicle


@dataclass
class Track:
    """A closed circuit: length [m], elevation harmonics, wind.

    Elevation z(s) = Σ amp·sin(2π·k·s/L + phase); heading goes once round (circle).
    Wind blows *from* ``wind_from_deg`` (clockwise from north) at ``wind_mps``.
    """

    length_m: float = 5500.0
    hills: tuple = ((14.0, 2, 0.0), (5.0, 5, 1.0))  # (amplitude m, harmonic k, phase rad)
    wind_mps: float = 3.0
    wind_from_deg: float = 225.0
    gust_mps: float = 0.7

    def elevation(self, s):
        return sum(a * np.sin(2 * np.pi * k * s / self.length_m + ph) for a, k, ph in self.hills)

    def grade(self, s):
        slope = sum(a * 2 * np.pi * k / self.length_m * np.cos(2 * np.pi * k * s / self.length_m + ph)
                    for a, k, ph in self.hills)
        return np.arctan(slope)

    def heading_deg(self, s):
        return (360.0 * s / self.length_m) % 360.0


@dataclass
class Noise:
    """Sensor and process noise (standard deviations)."""

    speed_mps: float = 0.02
    airspeed_mps: float = 0.10
    torque_nm: float = 0.5
    speed_rpm: float = 1.0
    imu_mps2: float = 0.05
    gps_elevation_m: float = 0.5
    process_w: float = 800.0
    process_rel: float = 0.03


@dataclass
class SynthOptions:
    minutes: float = 15.0
    seed: int = 0
    hz: float = 8.0
    vehicle: str = "prius3"
    truth: str = "drvpw_prius3"
    track: Track = field(default_factory=Track)
    noise: Noise = field(default_factory=Noise)
    max_power_w: float = 100_000.0      # system power of the 3rd-gen Prius (100 kW, 136 PS)
    ev_max_power_w: float = 35_000.0    # battery-limited EV-mode power
    regen_max_w: float = 30_000.0       # recuperation limit at the wheels
    max_accel_mps2: float = 3.5
    max_brake_mps2: float = 4.0         # firm braking (~0.4 g); harder braking in > 1 % of
    # samples reads as km/h mistaken for m/s to the log reader (99th pct > 4.5 m/s²)
    trip_id: str = "synth-1"


# ---- driver: phases of (name, controller) ------------------------------------------

def _phases(rng: np.random.Generator) -> list[tuple[str, dict]]:
    """The paper's analytical patterns, in order; each phase is a dict of settings."""
    ph = [("free", {"duration": 120.0, "vmax": 60 * KMH})]
    ph += [("max_accel", {"to": 160 * KMH}), ("cruise", {"v": 160 * KMH, "duration": 25.0}),
           ("max_brake", {"to": 0.0}), ("stop", {"duration": 5.0})]
    for v in (40, 60, 80, 100, 120, 140):
        ph += [("cruise", {"v": v * KMH, "duration": 35.0})]
    ph += [("coast", {"to": 30 * KMH}), ("cruise", {"v": 30 * KMH, "duration": 10.0})]
    for acc in (0.5, 1.0, 1.5):
        ph += [("const_accel", {"a": acc, "to": 100 * KMH}), ("cruise", {"v": 100 * KMH, "duration": 8.0}),
               ("const_accel", {"a": -acc, "to": 20 * KMH})]
    ph += [("brake_to", {"a": -2.0, "to": 0.0}), ("stop", {"duration": 5.0}),
           ("ev_max", {"to": 45 * KMH}), ("cruise", {"v": 45 * KMH, "duration": 10.0}),
           ("brake_to", {"a": -2.5, "to": 0.0}), ("stop", {"duration": 5.0}),
           ("max_accel", {"to": 120 * KMH}), ("coast", {"to": 60 * KMH}),
           ("free", {"duration": 240.0, "vmax": 100 * KMH}), ("brake_to", {"a": -2.0, "to": 0.0})]
    return ph


def _drive(opt: SynthOptions, truth: Equation, mass: float, rng: np.random.Generator):
    """Integrate the driver: returns speed [m/s], command accel [m/s²], phase name, EV flag."""
    dt = 1.0 / opt.hz
    n = int(round(opt.minutes * 60.0 * opt.hz))
    v = np.zeros(n)
    a = np.zeros(n)
    name = np.empty(n, dtype=object)
    ev = np.zeros(n, bool)
    phases = _phases(rng)
    jerk = 6.0 * dt
    k, pi, t_in = 0, 0, 0.0
    cur_v, cur_a = 0.0, 0.0
    target_free = 0.0
    s = 0.0
    while k < n:
        kind, p = phases[pi % len(phases)]
        if pi >= len(phases) and kind == "free":
            p = dict(p, duration=p["duration"] * (1 + rng.uniform(-0.3, 0.3)))
        done = False
        if kind == "max_accel":
            cmd = min(opt.max_accel_mps2, opt.max_power_w / (mass * max(cur_v, 1.0)))
            done = cur_v >= p["to"]
        elif kind == "ev_max":
            cmd = min(opt.max_accel_mps2, opt.ev_max_power_w / (mass * max(cur_v, 1.0)))
            done = cur_v >= p["to"]
        elif kind == "max_brake":
            cmd = -opt.max_brake_mps2
            done = cur_v <= p["to"] + 0.05
        elif kind in ("brake_to", "const_accel"):
            cmd = p["a"]
            done = (cur_v >= p["to"]) if p["a"] > 0 else (cur_v <= p["to"] + 0.05)
        elif kind == "cruise":
            cmd = np.clip(0.6 * (p["v"] - cur_v), -2.0, 1.5)
            done = t_in >= p["duration"]
        elif kind == "stop":
            cmd = -1.0 if cur_v > 0 else 0.0
            done = t_in >= p["duration"]
        elif kind == "coast":
            # zero powertrain power: the truth equation's road load decelerates the car
            th = float(opt.track.grade(s))
            x = Inputs(np.array([max(cur_v, 0.1)]), np.array([0.0]), np.array([th]),
                       np.array([0.0]), np.array([mass]), np.array([1.2]))
            cats = truth.category_powers(x)
            road = sum(float(cats[c][0]) for c in cats if c != "acc")
            cmd = -road / (truth.terms.get("acc", 1.0) * mass * max(cur_v, 0.1))
            done = cur_v <= p["to"]
        else:  # free: Ornstein-Uhlenbeck target speed with occasional stops
            if t_in == 0.0 or rng.random() < dt / 20.0:
                target_free = 0.0 if rng.random() < 0.15 else rng.uniform(0.2, 1.0) * p["vmax"]
            cmd = np.clip(0.35 * (target_free - cur_v), -2.5, 2.0)
            done = t_in >= p["duration"]
        if done:
            pi += 1
            t_in = 0.0
            continue
        cur_a += np.clip(cmd - cur_a, -jerk, jerk)
        new_v = cur_v + cur_a * dt
        if new_v < 0:
            new_v, cur_a = 0.0, 0.0
        v[k], a[k], name[k], ev[k] = cur_v, cur_a, kind, kind == "ev_max"
        s += 0.5 * (cur_v + new_v) * dt
        cur_v = new_v
        k += 1
        t_in += dt
    return v, a, name, ev


def synthesize(opt: SynthOptions | None = None,
               effects: tuple[Callable, ...] = ()) -> tuple[pd.DataFrame, dict]:
    """Generate a synthetic log and its truth.

    Parameters
    ----------
    opt : :class:`SynthOptions`
    effects : callables ``f(state: dict, rng) -> (extra_power_w, columns: dict)`` that add
        an undeclared load to the powertrain power and may log signals (for the residual
        tracer's tests); ``state`` holds arrays v, a, theta, wind, mass, rho, t, trip, power_w.

    Returns (DataFrame in the canonical schema, truth dict).
    """
    opt = opt or SynthOptions()
    rng = np.random.default_rng(opt.seed)
    veh: Vehicle = load_vehicle(opt.vehicle)
    truth = load_equation(opt.truth)
    mass = float(veh.mass_kg)
    dt = 1.0 / opt.hz
    v, a_cmd, phase, ev = _drive(opt, truth, mass, rng)
    n = len(v)
    t = np.arange(n) * dt
    # acceleration at the sample = central difference of the integrated speed
    a = np.gradient(v, dt)
    dist = np.r_[0.0, np.cumsum(0.5 * (v[1:] + v[:-1]) * dt)]
    theta = opt.track.grade(dist)
    heading = opt.track.heading_deg(dist)
    gust = np.zeros(n)
    for i in range(1, n):  # OU gusts, 10 s correlation
        gust[i] = gust[i - 1] * (1 - dt / 10.0) + opt.track.gust_mps * np.sqrt(2 * dt / 10.0) * rng.normal()
    wind_to = np.deg2rad(opt.track.wind_from_deg + 180.0)
    wind = (opt.track.wind_mps + gust) * np.cos(np.deg2rad(heading) - wind_to)
    ambient_c = 20.0 + 0.5 * np.sin(2 * np.pi * t / 3600.0)
    pressure_kpa = np.full(n, 100.8)
    rho = air_density(ambient_c, pressure_kpa)
    x = Inputs(v, a, theta, wind, np.full(n, mass), rho)
    p_truth = truth.power(x)
    p = p_truth + rng.normal(0.0, 1.0, n) * (opt.noise.process_w + opt.noise.process_rel * np.abs(p_truth))
    state = {"v": v, "a": a, "theta": theta, "wind": wind, "mass": np.full(n, mass), "rho": rho,
             "t": t, "trip": np.full(n, opt.trip_id, dtype=object), "power_w": p}
    extra_cols: dict = {}
    for eff in effects:
        dp, cols = eff(state, rng)
        p = p + dp
        state["power_w"] = p
        extra_cols.update(cols)
    # the powertrain cannot deliver at standstill, and recuperation is limited: friction
    # brakes take the rest (flagged, as a CAN log would)
    regen_lim = opt.regen_max_w * np.clip((v - 2.0) / 3.0, 0.0, 1.0)
    brake = p < -regen_lim - 1.0
    p_pt = np.where(brake, -regen_lim, p)
    p_pt = np.where(v < 0.05, 0.0, p_pt)

    pt = veh.powertrain
    S, R = float(pt["sun_teeth"]), float(pt["ring_teeth"])
    kr, kc, kf = float(pt.get("mg2_reduction", 1.0)), float(pt.get("counter_ratio", 1.0)), float(pt["final_drive"])
    r_wh = float(pt["wheel_radius_m"])
    inn = {k: veh.inertia(k) for k in ("ice", "carrier", "mg1", "sun", "ring", "mg2", "wheels")}
    w_wh = v / r_wh
    dw_wh = a / r_wh
    w_r = w_wh * kc * kf
    w_mg2 = w_r * kr
    # engine: on for high demand or above 70 km/h, never in EV-mode phases
    on = ((p_pt > 12_000.0) | (v > 70 * KMH)) & ~ev
    on = pd.Series(on).rolling(int(2 * opt.hz), center=True, min_periods=1).max().to_numpy().astype(bool) & ~ev
    p_e = np.where(on, np.clip(p_pt + 3_000.0, 4_000.0, 73_000.0), 0.0)
    rpm_target = np.where(on, 1000.0 + 4200.0 * (p_e / 73_000.0) ** 0.8, 0.0)
    rpm = pd.Series(rpm_target).ewm(alpha=dt / 0.5).mean().to_numpy()
    w_ice = rpm * RPM
    tau_ice = np.where(w_ice > 50.0, p_e / np.maximum(w_ice, 1e-9), 0.0)
    dw_ice = np.gradient(w_ice, dt)
    w_mg1 = ((R + S) * w_ice - R * w_r) / S
    dw_mg1 = np.gradient(w_mg1, dt)
    tau_c = tau_ice - dw_ice * (inn["ice"] + inn["carrier"])
    tau_mg1 = dw_mg1 * (inn["mg1"] + inn["sun"]) - (S / (R + S)) * tau_c
    tau_r_ice = (R / (R + S)) * tau_c
    j_wh = inn["ring"] * (kc * kf) ** 2 + inn["mg2"] * (kr * kc * kf) ** 2 + inn["wheels"]
    tau_wh = p_pt / np.maximum(w_wh, 0.5)
    tau_mg2 = (tau_wh - kc * kf * tau_r_ice + dw_wh * j_wh) / (kr * kc * kf)

    nz = opt.noise
    ns = lambda sd: rng.normal(0.0, sd, n)  # noqa: E731
    df = pd.DataFrame({
        "trip_id": opt.trip_id,
        "time_s": np.round(t, 4),
        "speed_mps": np.maximum(v + ns(nz.speed_mps), 0.0),
        "grade_rad": theta,
        "airspeed_mps": (v - wind) + ns(nz.airspeed_mps),
        "ambient_c": ambient_c,
        "pressure_kpa": pressure_kpa,
        "mass_kg": mass,
        "ice_speed_rpm": np.round(w_ice / RPM + ns(nz.speed_rpm) * on),
        "mg1_speed_rpm": np.round(w_mg1 / RPM + ns(nz.speed_rpm)),
        "mg1_torque_nm": tau_mg1 + ns(nz.torque_nm),
        "mg2_speed_rpm": np.round(w_mg2 / RPM + ns(nz.speed_rpm)),
        "mg2_torque_nm": tau_mg2 + ns(nz.torque_nm),
        "brake": brake,
        "reverse": False,
        "gps_elevation_m": opt.track.elevation(dist) + 30.0 + ns(nz.gps_elevation_m),
        "imu_accel_mps2": a + G * np.sin(theta) + ns(nz.imu_mps2),
        "heading_deg": heading,
        "engine_on": on,
        "ev_mode": ev,
        "phase": phase.astype(str),
    })
    for k, col in extra_cols.items():
        df[k] = col
    truth_doc = {
        "equation": truth.name, "terms": truth.terms, "mass_kg": mass,
        "vehicle": veh.name, "seed": opt.seed, "hz": opt.hz, "minutes": opt.minutes,
        "noise": asdict(opt.noise), "track": {k: v for k, v in asdict(opt.track).items()},
        "effects": [getattr(e, "describe", lambda: repr(e))() for e in effects],
        "note": ("measured power = truth equation with true speed, acceleration (central difference of "
                 "the driven speed), survey grade and wind, plus process noise; powertrain signals from "
                 "the inverse power-split model; brake flag where recuperation is exceeded"),
    }
    return df, truth_doc


def write_synth(df: pd.DataFrame, truth: dict, out) -> None:
    """Write a synthetic log (Parquet with truth metadata, or CSV plus ``.truth.json``)."""
    from pathlib import Path

    import pyarrow as pa

    from sumo_drvpw.fileio import write_json, write_parquet, write_text

    out = Path(out)
    if out.suffix.lower() == ".csv":
        from io import StringIO

        buf = StringIO()
        df.to_csv(buf, index=False)
        write_text(out, buf.getvalue())
        write_json(out.with_suffix(".truth.json"), truth)
        return
    table = pa.Table.from_pandas(df, preserve_index=False)
    meta = dict(table.schema.metadata or {})
    meta[b"sumo_drvpw.truth"] = json.dumps(truth, default=float).encode()
    write_parquet(out, table.replace_schema_metadata(meta))
