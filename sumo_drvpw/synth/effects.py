"""Planted effects for synthetic logs: loads the declared equation lacks, and distractors.

Each effect is a callable ``f(state, rng) -> (extra_power_w, {column: values})`` for
:func:`sumo_drvpw.synth.track.synthesize` (``state``: arrays v [m/s], a [m/s²], theta [rad],
wind [m/s], mass [kg], rho [kg/m³], t [s], trip, power_w [W]). The planted power of the
last call is kept in ``self.last_power_w`` (per trip in ``self.power_w``) so tests can
compute the noise floor from the truth. ``describe()`` names the effect for the
synthetic log's truth record. Sizes are realistic: a few per cent of driving energy.

:func:`synth_trips` concatenates several synthetic trips (distinct seeds and trip ids).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from sumo_drvpw.model.constants import G
from sumo_drvpw.model.equations import load_equation
from sumo_drvpw.model.terms import Inputs


def _ou(n: int, dt: float, tau_s: float, sd: float, rng, x0: float = 0.0) -> np.ndarray:
    """Ornstein–Uhlenbeck path (mean 0, stationary s.d. ``sd``, correlation time ``tau_s``)."""
    phi = np.exp(-dt / tau_s)
    e = rng.normal(0.0, sd * np.sqrt(1 - phi * phi), n)
    out = np.empty(n)
    x = x0
    # vectorized AR(1) through a linear filter
    from scipy.signal import lfilter

    out = lfilter([1.0], [1.0, -phi], e, zi=np.array([phi * x]))[0]
    return out


def _switching(n: int, dt: float, mean_on_s: float, mean_off_s: float, rng) -> np.ndarray:
    """A two-state (on/off) Markov signal with mean dwell times [s]."""
    out = np.zeros(n, bool)
    i, state = 0, bool(rng.random() < mean_on_s / (mean_on_s + mean_off_s))
    while i < n:
        dur = rng.exponential(mean_on_s if state else mean_off_s)
        k = max(1, int(round(dur / dt)))
        out[i:i + k] = state
        i += k
        state = not state
    return out


class _Effect:
    def __init__(self):
        self.power_w: dict = {}
        self.last_power_w = None

    def _keep(self, state, dp):
        self.last_power_w = dp
        self.power_w[str(state["trip"][0])] = dp
        return dp


class AuxLoad(_Effect):
    """An accessory load logged as a signal: A/C compressor power ``column`` [W] with an
    on/off flag ``flag``; the compressor cycles (mean 60 s on, 40 s off), runs only while
    moving (v > 0.5 m/s), and its level drifts between about 0.8 and 2.4 kW.

    Planted power [W] = ``gain`` × column (form ``[column]``: additive c·signal·v⁰).
    """

    def __init__(self, column: str = "ac_power_w", flag: str = "ac_on", level_w: float = 1600.0,
                 gain: float = 1.0):
        super().__init__()
        self.column, self.flag, self.level_w, self.gain = column, flag, level_w, gain

    def __call__(self, state, rng):
        v, t = state["v"], state["t"]
        dt = float(t[1] - t[0]) if len(t) > 1 else 1.0
        on = _switching(len(v), dt, 60.0, 40.0, rng) & (v > 0.5)
        level = np.clip(self.level_w + _ou(len(v), dt, 120.0, 400.0, rng), 800.0, 2400.0)
        sig = np.where(on, level, 0.0)
        return self._keep(state, self.gain * sig), {self.column: sig, self.flag: on}

    def describe(self):
        return f"AuxLoad: {self.gain:g} × [{self.column}] (A/C compressor, flag {self.flag})"


class TermScaledBySignal(_Effect):
    """A declared term changed by a logged signal: cold tyres roll harder.

    ``tyre_temp_c`` warms from ambient (2–10 °C) towards 45 °C with a 12-min time
    constant; the rolling coefficient changes by ``per_k`` per kelvin below ``ref_c``:
    planted power [W] = c_roll · per_k · (ref_c − T) · roll, i.e. the forms
    ``[tyre_temp_c]*roll`` (and ``roll``, already declared).
    """

    def __init__(self, term: str = "roll", column: str = "tyre_temp_c", per_k: float = 0.01,
                 ref_c: float = 45.0, truth: str = "drvpw_prius3"):
        super().__init__()
        self.term, self.column, self.per_k, self.ref_c = term, column, per_k, ref_c
        self.coef = float(load_equation(truth).terms[term])

    def __call__(self, state, rng):
        from sumo_drvpw.model.terms import parse_term

        t = state["t"]
        start = rng.uniform(2.0, 10.0)
        temp = self.ref_c - (self.ref_c - start) * np.exp(-(t - t[0]) / 720.0)
        temp = temp + _ou(len(t), float(t[1] - t[0]), 30.0, 0.5, rng)
        x = Inputs(state["v"], state["a"], state["theta"], state["wind"], state["mass"], state["rho"])
        term = parse_term(self.term).evaluate(x)
        dp = self.coef * self.per_k * (self.ref_c - temp) * term
        return self._keep(state, dp), {self.column: temp}

    def describe(self):
        return (f"TermScaledBySignal: {self.term} × (1 + {self.per_k:g}·({self.ref_c:g} − [{self.column}]))")


class SpeedFunction(_Effect):
    """A function of speed alone (the seed paper's residual was quadratic in speed):
    planted power [W] = Σ c_k·v^k while moving (v > 0.05 m/s; the synthetic powertrain
    delivers nothing at standstill), default 300 + 0.8·v² (≈ 0.9 kW at 100 km/h)."""

    def __init__(self, coefs: dict | None = None):
        super().__init__()
        self.coefs = dict(coefs or {0: 300.0, 2: 0.8})

    def __call__(self, state, rng):
        v = state["v"]
        dp = sum(c * v ** k for k, c in self.coefs.items()) * (v > 0.05)
        return self._keep(state, dp), {}

    def describe(self):
        return "SpeedFunction: " + " + ".join(f"{c:g}·v^{k}" for k, c in self.coefs.items())


class PerTripMass(_Effect):
    """A per-trip mass change (passengers, cargo) the log's ``mass_kg`` does not show:
    Δm drawn per trip from ``deltas_kg`` in turn (or N(0, sd_kg)); planted power [W] =
    Δm/m × (acc + grade + roll power of the truth equation)."""

    def __init__(self, deltas_kg=(120.0, -60.0, 0.0, 180.0, -100.0, 60.0), truth: str = "drvpw_prius3"):
        super().__init__()
        self.deltas_kg = tuple(deltas_kg)
        self.truth = load_equation(truth)
        self.i = 0
        self.drawn: dict = {}

    def __call__(self, state, rng):
        dm = self.deltas_kg[self.i % len(self.deltas_kg)]
        self.i += 1
        self.drawn[str(state["trip"][0])] = dm
        x = Inputs(state["v"], state["a"], state["theta"], state["wind"], state["mass"], state["rho"])
        cats = self.truth.category_powers(x)
        dp = dm / state["mass"] * (cats["acc"] + cats["grade"] + cats["roll"])
        return self._keep(state, dp), {}

    def describe(self):
        return f"PerTripMass: Δm per trip from {self.deltas_kg} kg on acc, grade, roll"


class Distractors(_Effect):
    """Columns that carry nothing: a random walk, white noise, an on/off flag, and a
    signal correlated with speed (cabin noise, R² ≈ 0.8 with v) without any effect."""

    def __call__(self, state, rng):
        v, t = state["v"], state["t"]
        n = len(v)
        dt = float(t[1] - t[0]) if n > 1 else 1.0
        cols = {
            "random_walk": np.cumsum(rng.normal(0.0, 0.05, n)),
            "white_noise": rng.normal(0.0, 1.0, n),
            "wiper_on": _switching(n, dt, 30.0, 90.0, rng),
            "cabin_noise_db": 45.0 + 0.9 * v + rng.normal(0.0, 4.0, n),
        }
        return self._keep(state, np.zeros(n)), cols

    def describe(self):
        return "Distractors: random_walk, white_noise, wiper_on, cabin_noise_db (no effect)"


class Pedal(_Effect):
    """A response column: an accelerator pedal that follows the power demand (truth, noise
    and the effects before it), ``throttle_pct`` = 100·clip(P/``p_max_w``, 0, 1) + noise
    (s.d. ``noise_pct``). It plants no power: it *is* the demand, seen through the
    driver, and must never be reported as an effect the model lacks."""

    def __init__(self, p_max_w: float = 60e3, noise_pct: float = 3.0):
        super().__init__()
        self.p_max_w, self.noise_pct = p_max_w, noise_pct

    def __call__(self, state, rng):
        p = np.asarray(state["power_w"], float)
        pedal = 100.0 * np.clip(p / self.p_max_w, 0.0, 1.0) + rng.normal(0.0, self.noise_pct, len(p))
        return self._keep(state, np.zeros(len(p))), {"throttle_pct": np.clip(pedal, 0.0, 100.0)}

    def describe(self):
        return "Pedal: throttle_pct follows the power demand (a response, no effect)"


def _shift(x: np.ndarray, k: int) -> np.ndarray:
    """x(i − k): the signal k samples late (edge value held)."""
    if k == 0:
        return x.copy()
    if k > 0:
        return np.r_[np.full(k, x[0]), x[:-k]]
    return np.r_[x[-k:], np.full(-k, x[-1])]


class PowerLag(_Effect):
    """Timing: the logged power is ``lag_s`` late relative to speed (a slow power channel,
    or an OBD speed that leads it): planted power [W] = P(t − lag) − P(t), so the power
    column reads P(t − lag). Structural: no column names it; put it after the other
    effects (it delays them too)."""

    def __init__(self, lag_s: float = 1.5):
        super().__init__()
        self.lag_s = lag_s

    def __call__(self, state, rng):
        p = np.asarray(state["power_w"], float)
        t = state["t"]
        dt = float(t[1] - t[0]) if len(t) > 1 else 1.0
        k = int(round(self.lag_s / dt))
        return self._keep(state, _shift(p, k) - p), {}

    def describe(self):
        return f"PowerLag: power logged {self.lag_s:g} s late"


class RecuperationEfficiency(_Effect):
    """Regimes: recuperation on its own coefficient (drivetrain efficiency differs by
    direction): planted power [W] = (factor − 1)·min(P, 0)."""

    def __init__(self, factor: float = 0.75):
        super().__init__()
        self.factor = factor

    def __call__(self, state, rng):
        p = np.asarray(state["power_w"], float)
        return self._keep(state, (self.factor - 1.0) * np.minimum(p, 0.0)), {}

    def describe(self):
        return f"RecuperationEfficiency: recuperation × {self.factor:g}"


class InertiaByDirection(_Effect):
    """Regimes: the drivetrain delivers kinetic energy at 1/η and returns it at η, so while
    the car speeds up the inertial power costs more: planted power [W] = k·m·v·max(a, 0)
    (the ``acc_pos`` term; k 0.25 reads with acc 1.05 as η ≈ 0.9)."""

    def __init__(self, k: float = 0.25):
        super().__init__()
        self.k = k

    def __call__(self, state, rng):
        m, v, a = (np.asarray(state[c], float) for c in ("mass", "v", "a"))
        return self._keep(state, self.k * m * v * np.maximum(a, 0.0)), {}

    def describe(self):
        return f"InertiaByDirection: + {self.k:g}·m·v·max(a, 0) while speeding up"


class RecuperationLimit(_Effect):
    """Regimes: beyond ``limit_w`` of recuperation friction brakes take over, unflagged:
    planted power [W] = max(P, −limit) − P (measured power stops following the model)."""

    def __init__(self, limit_w: float = 8000.0):
        super().__init__()
        self.limit_w = limit_w

    def __call__(self, state, rng):
        p = np.asarray(state["power_w"], float)
        return self._keep(state, np.maximum(p, -self.limit_w) - p), {}

    def describe(self):
        return f"RecuperationLimit: recuperation capped at {self.limit_w / 1000:g} kW, brakes unflagged"


class AltitudeAir(_Effect):
    """Air density from altitude: trips at different altitudes (``altitudes_m`` in turn,
    ±30 m relief); the true ρ follows the standard-atmosphere pressure there while the log
    (drop its ``pressure_kpa`` column) lets the reader assume sea level. Logs
    ``elevation_m``; planted power [W] = aero power of the truth × (p(h)/p_state − 1)."""

    def __init__(self, altitudes_m=(0.0, 600.0, 1200.0, 300.0, 900.0, 1500.0), truth: str = "drvpw_prius3"):
        super().__init__()
        self.altitudes_m = tuple(altitudes_m)
        self.truth = load_equation(truth)
        self.i = 0

    def __call__(self, state, rng):
        from sumo_drvpw.fit.diagnose.structural import pressure_at_altitude_kpa

        h0 = self.altitudes_m[self.i % len(self.altitudes_m)]
        self.i += 1
        t = state["t"]
        h = h0 + 30.0 * np.sin(2 * np.pi * (t - t[0]) / 400.0)
        x = Inputs(state["v"], state["a"], state["theta"], state["wind"], state["mass"], state["rho"])
        aero = self.truth.category_powers(x)["aero"]
        # the synthetic log's pressure is 100.8 kPa (track.synthesize)
        dp = aero * (pressure_at_altitude_kpa(h) / 100.8 - 1.0)
        return self._keep(state, dp), {"elevation_m": h}

    def describe(self):
        return f"AltitudeAir: trips at {self.altitudes_m} m, ρ from altitude"


class AttenuatedGrade(_Effect):
    """Grade measurement: the logged grade is the true one smoothed over ``window_s`` and
    attenuated by ``factor`` (coarse elevation), while the accelerometer column
    ``imu_accel_mps2`` (dv/dt + g·sin θ + noise) stays true. Plants no power."""

    def __init__(self, factor: float = 0.5, window_s: float = 20.0):
        super().__init__()
        self.factor, self.window_s = factor, window_s

    def __call__(self, state, rng):
        t = state["t"]
        dt = float(t[1] - t[0]) if len(t) > 1 else 1.0
        w = max(1, int(round(self.window_s / dt)))
        sm = pd.Series(state["theta"]).rolling(w, center=True, min_periods=1).mean().to_numpy()
        return self._keep(state, np.zeros(len(t))), {"grade_rad": self.factor * sm}

    def describe(self):
        return f"AttenuatedGrade: logged grade = {self.factor:g} × true grade smoothed over {self.window_s:g} s"


class LogPower(_Effect):
    """Logs the driving power itself as ``power_w`` (truth + process noise + the effects
    before it), which the drive-log spec lets a log carry; put it last. With it the
    measured power skips the power-split reconstruction, so the noise floor is the
    planted process noise. It also logs the acceleration (``accel_mps2``, as an
    accelerometer would), so the acceleration is not differentiated from a noisy speed."""

    def __call__(self, state, rng):
        return self._keep(state, np.zeros(len(state["v"]))), {"power_w": np.array(state["power_w"], float),
                                                              "accel_mps2": np.array(state["a"], float)}

    def describe(self):
        return "LogPower: power_w column = driving power"


class BatteryLog(_Effect):
    """A battery log behind the driving power: battery V·I from a known energy chain, plus an
    undeclared auxiliary load at standstill (issue #12 §3: what the road adds).

    Logs ``battery_voltage_v`` (``voltage_v`` ± 2 % ripple) and ``battery_current_a`` with
    P_bat = chain(P) + ``standstill_aux_w``·[v < 0.1 m/s] + N(0, ``noise_w``), P the driving
    power so far (truth + process noise + earlier effects; put this effect last), chain:
    η_t = ``traction_efficiency``, η_r = ``recuperation_efficiency``, constant
    ``aux_power_w``. Adds no driving power; ``self.last_power_w`` is the planted standstill
    power [W at the battery]. ``standstill_aux_w = 0`` plants nothing (the null case).
    """

    def __init__(self, standstill_aux_w: float = 450.0, traction_efficiency: float = 0.9,
                 recuperation_efficiency: float = 0.8, aux_power_w: float = 300.0,
                 voltage_v: float = 360.0, noise_w: float = 300.0):
        super().__init__()
        self.standstill_aux_w, self.aux_power_w, self.voltage_v = standstill_aux_w, aux_power_w, voltage_v
        self.traction_efficiency, self.recuperation_efficiency = traction_efficiency, recuperation_efficiency
        self.noise_w = noise_w
        self.battery_w: dict = {}

    def chain(self):
        """The declared chain (without the planted standstill load)."""
        from sumo_drvpw.model.chain import EnergyChain

        return EnergyChain("battery", self.traction_efficiency, self.recuperation_efficiency,
                           aux_power_w=self.aux_power_w)

    def __call__(self, state, rng):
        from sumo_drvpw.model.constants import STANDSTILL_MPS

        v = np.asarray(state["v"], float)
        p = np.asarray(state["power_w"], float)
        plant = self.standstill_aux_w * (v < STANDSTILL_MPS)
        pb = self.chain().evaluate(p, v)["power_w"] + plant + rng.normal(0.0, self.noise_w, v.size)
        volt = self.voltage_v * (1.0 + 0.02 * np.sin(2 * np.pi * state["t"] / 600.0))
        self.battery_w[str(state["trip"][0])] = pb
        self._keep(state, plant)
        return np.zeros(v.size), {"battery_voltage_v": volt, "battery_current_a": pb / volt}

    def describe(self):
        return (f"BatteryLog: battery V·I from a chain (η_t {self.traction_efficiency:g}, η_r "
                f"{self.recuperation_efficiency:g}, aux {self.aux_power_w:g} W) + {self.standstill_aux_w:g} W "
                "at standstill")


def synth_trips(n_trips: int = 4, minutes: float = 10.0, seed: int = 0, effects=(), **kw):
    """Concatenate ``n_trips`` synthetic trips (seeds seed…seed+n−1, ids synth-1…).

    Returns (DataFrame, list of truth dicts). ``kw`` go to :class:`SynthOptions`.
    """
    from sumo_drvpw.synth.track import SynthOptions, synthesize

    frames, truths = [], []
    for i in range(n_trips):
        df, truth = synthesize(SynthOptions(minutes=minutes, seed=seed + i, trip_id=f"synth-{i + 1}", **kw),
                               effects=tuple(effects))
        frames.append(df)
        truths.append(truth)
    return pd.concat(frames, ignore_index=True), truths


def energy_counters(time_s, battery_w, step_j: float) -> tuple[np.ndarray, np.ndarray]:
    """A BMS's cumulative counters of one trip's battery power ``battery_w`` [W] (+ discharging):
    energy discharged and charged [J], each sample's power held to the next sample, counted in
    whole steps of ``step_j`` (each step reported as it is crossed; sumo_drvpw.data.counters)."""
    w = np.r_[np.diff(time_s), 0.0]
    p = np.asarray(battery_w, float)
    return tuple(np.floor(np.cumsum(np.clip(x, 0, None) * w) / step_j) * step_j for x in (p, -p))


def counter_drive(trips: int = 4, seconds: float = 600.0, step_j: float = 7200.0, seed: int = 0) -> pd.DataFrame:
    """An EV's stop-and-go drive at 10 Hz with a planted chain — 90 % out, 70 % back, 400 W
    auxiliary, on a road load acc 1, v1 150, v3 0.4 at 1500 kg — whose battery is logged
    only as the BMS's energy counters in steps of ``step_j`` (:func:`energy_counters`);
    the battery power they count is kept as ``true_battery_w``."""
    from sumo_drvpw.data.counters import COUNTERS

    rng = np.random.default_rng(seed)
    out = []
    for k in range(trips):
        t = np.arange(0.0, seconds, 0.1)
        v = np.clip(12.0 + 9.0 * np.sin(2 * np.pi * t / rng.uniform(50, 90) + rng.uniform(0, 6))
                    + 3.0 * np.sin(2 * np.pi * t / 11.0), 0.0, None)
        a = np.gradient(v, t)
        wheel = 1500.0 * v * a + 150.0 * v + 0.4 * v ** 3
        batt = np.where(wheel > 0, wheel / 0.9, wheel * 0.7) + 400.0
        d, c = energy_counters(t, batt, step_j)
        out.append(pd.DataFrame({"trip_id": f"T{k}", "time_s": t, "speed_mps": v, "accel_mps2": a, "mass_kg": 1500.0,
                                 COUNTERS[0]: d, COUNTERS[1]: c, "true_battery_w": batt}))
    return pd.concat(out, ignore_index=True)


def planted_power(effects, trip_ids) -> np.ndarray:
    """Planted power [W] per row of a :func:`synth_trips` log (rows in trip order)."""
    parts = []
    for tid in pd.unique(np.asarray(trip_ids)):
        tot = None
        for e in effects:
            if isinstance(e, (LogPower, BatteryLog)):
                continue
            dp = e.power_w[str(tid)]
            tot = dp if tot is None else tot + dp
        parts.append(tot)
    return np.concatenate(parts)


def plant_dropout(df: pd.DataFrame, trip: str, start_s: float, duration_s: float,
                  mode: str = "hold") -> np.ndarray:
    """A logger dropout planted in a synthetic log, in place: within ``trip`` from
    ``start_s`` for ``duration_s`` every numeric column except time holds its value at the
    start (``mode="hold"``, a frozen logger) or runs in a straight line to its value at the
    end (``"linear"``, a gap filled by interpolation). Returns the mask of the planted rows
    (the rows strictly inside the window; the row at the start, and in linear mode at the
    end, keeps its real value)."""
    if mode not in ("hold", "linear"):
        raise ValueError(f"mode must be 'hold' or 'linear', got {mode!r}")
    t = df["time_s"].to_numpy(float)
    i = np.flatnonzero(df["trip_id"].to_numpy() == trip)
    t0 = t[i][0] + start_s
    a = i[np.searchsorted(t[i], t0)]
    b = i[np.searchsorted(t[i], t0 + duration_s)]
    cols = [c for c in df.columns if c != "time_s" and pd.api.types.is_float_dtype(df[c])]
    for c in cols:
        x = df[c].to_numpy(float).copy()
        if mode == "hold":
            x[a + 1:b + 1] = x[a]
        else:
            w = (t[a:b + 1] - t[a]) / (t[b] - t[a])
            x[a:b + 1] = x[a] + w * (x[b] - x[a])
        df[c] = x
    mask = np.zeros(len(df), bool)
    mask[a + 1:b + (1 if mode == "hold" else 0)] = True
    return mask


#: The one table of planted effects: name (as ``synth --plant`` takes it) → class; every
#: class builds with its defaults.
PLANTS = {"ac": AuxLoad, "cold-tyres": TermScaledBySignal, "speed-quadratic": SpeedFunction,
          "trip-mass": PerTripMass, "distractors": Distractors, "pedal": Pedal,
          "power-lag": PowerLag, "recuperation-efficiency": RecuperationEfficiency,
          "recuperation-limit": RecuperationLimit, "altitude-air": AltitudeAir,
          "attenuated-grade": AttenuatedGrade, "log-power": LogPower,
          "battery-standstill-aux": BatteryLog}

__all__ = ["AuxLoad", "TermScaledBySignal", "SpeedFunction", "PerTripMass", "Distractors",
           "Pedal", "PowerLag", "RecuperationEfficiency", "RecuperationLimit", "AltitudeAir",
           "AttenuatedGrade", "LogPower", "BatteryLog", "synth_trips", "planted_power", "plant_dropout", "PLANTS",
           "G"]
