"""The powertrain's energy chain as data: from driving power to battery or tank.

An equation file may carry a ``[chain]`` table after its road-load terms. The road-load
equation gives the driving power P [W] at the wheels (or the powertrain output); the
chain turns it into what a user pays for::

    [chain]
    predicts = "battery"              # wheel | powertrain_output | battery | fuel
    traction_efficiency = 0.90        # η_t (0, 1]; or a table, see below
    recuperation_efficiency = 0.75    # η_r (0, 1]
    recuperation_limit_w = 40000      # optional: braking power beyond it goes to the friction brakes [W]
    recuperation_by_decel_mps2 = 0    # optional: SUMO's recuperationEfficiencyByDecel k: recuperation
                                      #   × exp(−k/|a|) (a ≠ 0; the acceleration a from the SUMO loop or a log)
    aux_power_w = 300                 # constant auxiliary power P_aux,0 ≥ 0 [W]
    standstill_aux_w = 0              # optional: auxiliary power while standing (v < 0.1 m/s) minus that while
                                      #   moving [W]; aux_power_w + standstill_aux_w ≥ 0 (negative: drawn only
                                      #   while moving, e.g. drivetrain no-load losses, cooling)
    [chain.loads]                     # logged loads: column → gain [W/W] ≥ 0
    heater_power_w = 1.0
    [chain.hvac]                      # optional temperature-dependent HVAC power
    column = "ambient_c"              # ambient temperature column [°C]
    setpoint_c = 20.0
    heating_w_per_k = 150.0           # P = h_heat·max(T_set − T, 0) + h_cool·max(T − T_set, 0)
    cooling_w_per_k = 50.0
    warmup_j_per_k = 60000.0          # optional: heat to bring a cold cabin to T_set at a
                                      #   cold start [J per K below T_set], booked once per
                                      #   departure that starts cold (like a fuel cold start)
    [chain.traction_efficiency]       # a table instead of a constant (linear interpolation,
    speed_mps = [0, 10, 30]           #   held constant beyond the ends): axes speed_mps and/or
    power_w = [0, 20000, 60000]       #   power_w (|P|), values shaped (len(speed), len(power))
    values = [[0.8, 0.9, 0.9], ...]

Battery (``predicts = "battery"``), battery power positive when discharging::

    P_trac = max(P, 0) / η_t(v, P)
    P_rec  = η_r(v, P) · max(min(P, 0), −P_lim)                    (≤ 0)
    P_aux  = P_aux,0 + Σ g_k·L_k + h_heat·max(T_set − T, 0) + h_cool·max(T − T_set, 0)
             + P_stand·[v < v_stand]      (P_stand: ``standstill_aux_w``, v_stand = STANDSTILL_MPS)
    P_bat  = P_trac + P_rec + P_aux       (P_aux accrues at standstill too)

``powertrain_output`` is the same without auxiliaries (η are the transmission's).
``wheel`` returns P unchanged.

Fuel (``predicts = "fuel"``), a Willans line with engine-off (power-split hybrid)::

    P_eng  = max(P, 0) / η_t + P_aux                      (engine output demand) [W]
    on     = (P > P_off  or  v > v_on)  and not (v > v_0 and P < P_cut)     (engine fuelled)
    P_fuel = on · (P_idle,fuel + P_eng / η_m)             [W of fuel, lower heating value]
    P_fuel = on · P_idle,fuel + (P_eng + η_rt · max(min(P, 0), −P_lim) / η_t) / η_m
                                                          (``charge_sustaining = true``)
    fuel rate [L/s] = P_fuel / (LHV · ρ_fuel);  CO₂ [kg/s] = P_fuel / LHV · c_CO₂

with ``idle_fuel_power_w`` (P_idle,fuel ≥ 0), ``marginal_efficiency`` (η_m, (0, 1]),
``engine_off_below_w`` (P_off; ``-inf``: a conventional engine that runs the whole trip,
idling at stops), optional ``engine_on_above_mps`` (v_on), optional ``fuel_cut_below_w``
(P_cut: overrun fuel cut-off — while the vehicle moves (v above STANDSTILL_MPS, v_0), a
driving power below P_cut, typically 0, means the wheels turn the engine and its injection
is cut: no fuel; standing, it idles; declared, kept, not fitted by calibration),
``charge_sustaining`` (a declared hybrid whose battery drives below P_off: the engine puts
that energy back later, so it is booked at the margin all the same and only the idle fuel
stops with the engine; default false, the engine-off power free), for such a hybrid
``recuperation_round_trip`` (η_rt in [0, 1], default 0: none; its braking energy at the wheels
that the battery gives back at the wheels, capped at ``recuperation_limit_w`` P_lim, its
motor's power: the engine output it replaces is credited at the margin when the vehicle
brakes, so a braking sample books negative fuel, the battery's credit a later sample uses, as a
battery chain's recuperation does; declared, kept, not fitted; ``battery_usable_j``: only what
its battery's usable window holds, :mod:`sumo_drvpw.model.chain_buffer`; ``[chain.depleting]``:
a plug-in hybrid's battery spent first, :mod:`sumo_drvpw.model.chain_plugin`) and ``fuel``
(a key of :data:`sumo_drvpw.model.constants.FUELS`). Optional: ``moving_idle_fuel_power_w``
(≥ P_idle,fuel; default P_idle,fuel) replaces P_idle,fuel while moving (v ≥ v_0: friction at road
engine speed), ``engine_max_w`` caps P_eng (the demand above it is ``over_engine_w``, not delivered).
``cold_start_fuel_l`` (≥ 0, default 0)
is the extra fuel of one start of a cold engine [L] (warm-up enrichment, catalyst
heating, cold oil) at the air temperature ``cold_start_ref_c`` (default 23.9 °C, the
FTP's 75 °F), plus ``cold_start_fuel_l_per_k`` (≥ 0) for every kelvin colder::

    V_cold(T) = V_ref + s · max(T_ref − T, 0)      [L per start]

a per-trip quantity booked where a trip is known to start cold — in SUMO from a vehicle's
departure when the run says so (``[vehicles] cold_start``), at the run's air temperature,
as a rate decaying with FUEL_COLD_START_TAU_S (constants.py); a log does not say whether its engine
started cold, so calibration and log comparisons leave it out
(:meth:`EnergyChain.cold_start`). ``running_fuel_per_k`` (≥ 0, default 0) is the warm
engine's extra fuel in the cold, a share of the fuel power per kelvin below
``cold_start_ref_c`` (denser oil in the driveline, cooler tyres and engine)::

    P_fuel(T) = P_fuel · (1 + r · max(T_ref − T, 0))

with T the air temperature ``ambient_c`` (the HVAC's column when the chain has one): the log's
where it has one (unknown: no factor), in SUMO the run's air temperature (none given: the
default air's 20 °C, as for the HVAC and cold starts, and the run says so). Measured fuel is
corrected for the hybrid battery's energy change before it is compared (``battery_to_fuel``:
fuel energy per unit of battery energy, default 1/η_m; see :func:`corrected_fuel_power`).
A ``[chain.motor]`` table is SUMO's MMPEVEM motor and battery (:mod:`sumo_drvpw.model.mmpevem`).

Sources: the battery form is the usual BEV energy balance (e.g. Fiori, Ahn & Rakha,
Applied Energy 168 (2016) 257–268, Eq. 8–10; SUMO's Energy model, Kurczveil et al. 2014);
the Willans line is Rizzoni, Guzzella & Baumann, IEEE/ASME Trans. Mechatronics 4(3)
(1999) 246–257; the battery correction of hybrid fuel follows SAE J1711 (2010), §4.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.chain_buffer import _durations, _starts, buffered_return
from sumo_drvpw.model.chain_plugin import on_battery, plug_in
from sumo_drvpw.model.chain_values import Efficiency, Table  # noqa: F401
from sumo_drvpw.model.chain_values import engine_demand
from sumo_drvpw.model import chain_values as _values
from sumo_drvpw.model.constants import FUELS, STANDSTILL_MPS

#: keys a fuel chain must give (docs/energy-chain.md): no default describes an engine
FUEL_REQUIRED = ("fuel", "marginal_efficiency", "idle_fuel_power_w", "engine_off_below_w")
#: (their home before chain_values.py)
corrected_fuel_power, fuel_j_per_l = _values.corrected_fuel_power, _values.fuel_j_per_l


@dataclass
class EnergyChain:
    """Driving power → battery or fuel power; parameters as in the module docstring.

    Units: efficiencies [-], powers [W], gains [W/W] or [W/K], speeds [m/s].
    """

    predicts: str = "battery"
    traction_efficiency: Efficiency = 1.0
    recuperation_efficiency: Efficiency = 1.0
    recuperation_limit_w: float | None = None
    recuperation_by_decel_mps2: float = 0.0
    aux_power_w: float = 0.0
    standstill_aux_w: float = 0.0
    loads: dict[str, float] = field(default_factory=dict)
    hvac: dict | None = None
    idle_fuel_power_w: float = 0.0
    marginal_efficiency: float = 1.0
    engine_off_below_w: float = 0.0
    engine_on_above_mps: float | None = None
    fuel_cut_below_w: float | None = None
    charge_sustaining: bool = False
    recuperation_round_trip: float = 0.0
    #: a hybrid's usable battery window [J] for its round trip (model/chain_buffer.py); None: unbounded
    battery_usable_j: float | None = None
    #: a plug-in hybrid's charge-depleting battery (model/chain_plugin.py Depleting); None: none
    depleting: object | None = None
    fuel: str = "gasoline"
    battery_to_fuel: float | None = None
    cold_start_fuel_l: float = 0.0
    cold_start_fuel_l_per_k: float = 0.0
    cold_start_ref_c: float = 23.9
    running_fuel_per_k: float = 0.0
    moving_idle_fuel_power_w: float | None = None
    engine_max_w: float | None = None
    #: SUMO's MMPEVEM motor and battery (model/mmpevem.py SumoMotor), in place of η_t, η_r
    motor: object | None = None
    std_err: dict = field(default_factory=dict)
    reading: dict = field(default_factory=dict)
    provenance: dict = field(default_factory=dict)
    metrics: dict = field(default_factory=dict)
    #: keys of :data:`FUEL_REQUIRED` its file left out (a declaration for ``calibrate``), and that file
    missing: tuple = field(default=(), compare=False, repr=False)
    where: str = field(default="<equation>", compare=False, repr=False)

    def require_complete(self) -> None:
        """UserError where a fuel chain that leaves out its engine's keys is to predict fuel: no
        default describes an engine (η_m 1, no idle fuel, off at rest, petrol)."""
        if self.missing:
            raise UserError(f"{self.where} [chain]: predicts = \"fuel\" needs {', '.join(map(repr, self.missing))}: "
                            "the engine's fuel (one of " + ", ".join(FUELS) + "), its marginal efficiency η_m, its "
                            "idle fuel power [W] and the driving power below which it stops [W] (-inf: a "
                            "conventional engine that runs at rest; 0: a hybrid's, off at rest) — none has a "
                            "default an engine has (a calibration on the fuel target fits them)")

    @property
    def temperature_column(self) -> str:
        """The air-temperature column the chain reads (HVAC, warm-running fuel factor)."""
        return str((self.hvac or {}).get("column", "ambient_c"))

    @property
    def signals(self) -> set[str]:
        """Log columns the chain reads (loads, and the temperature of the HVAC or of the
        warm-running fuel factor)."""
        s = set(self.loads)
        if self.hvac or self.running_fuel_per_k:
            s.add(self.temperature_column)
        return s

    @property
    def required_signals(self) -> set[str]:
        """The :attr:`signals` a log must have: the loads and the HVAC's temperature. The
        warm-running factor's temperature is read where a log has it; a log without it
        (a dynamometer test at the reference temperature) gets no factor, and a comparison
        says so (:meth:`unknown_inputs`)."""
        return set(self.loads) | ({self.temperature_column} if self.hvac else set())

    def target_power(self, p_drive_w, v_mps, signals: dict | None = None, battery_w=None,
                     accel=None, grade=None, dt_s=None, trip=None) -> np.ndarray:
        """The chain's prediction in the form its measurement takes [W]: battery power, or
        fuel power less k·P_bat when the hybrid battery's V·I ``battery_w`` is given (so a
        state-of-charge swing is not a fuel error; k = :attr:`battery_fuel_factor`). ``accel``
        [m/s²], ``grade`` [rad]: what a recuperation by deceleration or a motor reads; ``dt_s``, ``trip``:
        a hybrid's battery window, carried through each trip (:meth:`evaluate`)."""
        signals = {**(signals or {}), **({"accel_mps2": accel} if accel is not None and self.reads_accel else {}),
                   **({"grade_rad": grade} if grade is not None and self.motor is not None else {})}
        pred = self.evaluate(p_drive_w, v_mps, dt_s, signals, trip)["power_w"]
        if self.predicts == "fuel" and battery_w is not None:
            pred = pred - self.battery_fuel_factor * np.asarray(battery_w, float)
        return pred

    @property
    def reads_accel(self) -> bool:
        """Whether it reads the acceleration ``accel_mps2`` (recuperation by deceleration, a motor)."""
        return bool(self.recuperation_by_decel_mps2) or self.motor is not None

    def unknown_inputs(self, signals: dict | None, n: int, trip=None) -> dict:
        """The chain's inputs (declared loads, HVAC temperature) that are unknown (NaN) on
        some of ``n`` samples: ``{column: {"samples", "read_as", "trips"}}`` (trips only
        when ``trip`` is given). :meth:`evaluate` reads an unknown load as no draw and an
        unknown temperature as the set-point (no HVAC): a report says where."""
        out = {}
        for col in sorted(self.signals):
            x = np.asarray((signals or {}).get(col, np.nan), float)
            bad = np.broadcast_to(~np.isfinite(x), (n,))
            if not bad.any():
                continue
            temp = col == self.temperature_column and col not in self.loads
            d = {"samples": int(bad.sum()),
                 "read_as": ("no load" if not temp else "the set-point (no HVAC)" if self.hvac
                             else "the reference temperature (no warm-running factor)")}
            if trip is not None:
                d["trips"] = [str(t) for t in np.unique(np.asarray(trip)[bad])]
            out[col] = d
        return out

    @property
    def fuel_props(self) -> dict:
        return FUELS[self.fuel]

    # ------------------------------------------------------------------ evaluation
    def auxiliary(self, n: int, signals: dict | None = None) -> np.ndarray:
        """Auxiliary power [W] per sample: constant + Σ gain·load + HVAC(T)."""
        p = np.full(n, self.aux_power_w)
        sig = signals or {}
        for col, gain in self.loads.items():
            p = p + gain * _signal(sig, col, n)
        if self.hvac:
            ts = float(self.hvac.get("setpoint_c", 20.0))
            # an unknown temperature books no HVAC (as the term grammar's 'cold' does), not
            # the heating of 0 °C
            t = _signal(sig, self.temperature_column, n, missing=ts)
            p = p + float(self.hvac.get("heating_w_per_k", 0.0)) * np.maximum(ts - t, 0.0)
            p = p + float(self.hvac.get("cooling_w_per_k", 0.0)) * np.maximum(t - ts, 0.0)
        return p

    def evaluate(self, p_drive_w, v_mps, dt_s=None, signals: dict | None = None, trip=None,
                 stored_j=None, spent_j=None) -> dict:
        """Battery or fuel power per sample from driving power (vectorized); a fuel chain read
        from a file without its engine's keys is refused (:meth:`require_complete`).

        Parameters
        ----------
        p_drive_w : driving power of the road-load equation [W]
        v_mps : speed [m/s]
        dt_s : sample durations [s] (scalar or array); when given, energies [J] (and for fuel,
            litres and kg CO₂) per sample are added as ``*_j`` / ``fuel_l`` / ``co2_kg``
        signals : column → array for the loads and the HVAC temperature
        trip, stored_j : a hybrid's battery window (``battery_usable_j``, needs ``dt_s``): one series,
            empty at each ``trip``'s start, or one vehicle a sample, ``stored_j`` [J] before (chain_buffer.py);
            ``spent_j``: a plug-in hybrid's battery energy spent, the same way (chain_plugin.py)

        Returns
        -------
        dict of arrays. Battery / powertrain output: ``traction_w``, ``recuperated_w`` (≤ 0),
        ``auxiliary_w``, ``friction_brake_w`` (≤ 0, braking power beyond the limit),
        ``power_w`` (net). Fuel: ``engine_on`` (bool), ``engine_w``, ``power_w`` (fuel power,
        LHV), ``fuel_lps`` [L/s], ``co2_kgps`` [kg/s]. Wheel: ``power_w``.
        """
        self.require_complete()
        p = np.asarray(p_drive_w, float)
        v = np.asarray(v_mps, float)
        v = v if v.shape == p.shape else np.broadcast_to(v, p.shape)  # (a step's few vehicles: no view to build)
        n = p.size
        if self.predicts == "wheel":
            out = {"power_w": p.copy()}
        elif self.predicts == "fuel":
            out = self._fuel(p, v, n, signals, dt_s, trip, stored_j) if self.depleting is None else \
                self._plug_in(p, v, n, signals, dt_s, trip, stored_j, spent_j)
        else:
            out = self._battery(p, v, n, signals)
        if dt_s is not None:
            dt = np.asarray(dt_s, float)  # a scalar multiplies as its broadcast does, bit for bit
            for k in [k for k in out if k.endswith("_w")]:
                out[k[:-2] + "_j"] = out[k] * dt
            if self.predicts == "fuel":
                out["fuel_l"] = out["fuel_lps"] * dt
                out["co2_kg"] = out["co2_kgps"] * dt
        return out

    def _battery(self, p, v, n, signals) -> dict:
        if self.motor is not None:  # the chain's auxiliary draws (P_const, loads, HVAC, standing) at its battery
            return self.motor.battery(p, v, signals, self.auxiliary(n, signals) + self.standstill_aux_w * (v < STANDSTILL_MPS))
        pos = np.maximum(p, 0.0)
        neg = np.minimum(p, 0.0)
        if self.recuperation_limit_w is not None:
            rec_mech = np.maximum(neg, -self.recuperation_limit_w)
        else:
            rec_mech = neg
        trac = pos / _eval(self.traction_efficiency, v, p)
        rec = _eval(self.recuperation_efficiency, v, p) * rec_mech
        if self.recuperation_by_decel_mps2:  # SUMO's exp(−k/|a|) where a ≠ 0
            a = (signals or {}).get("accel_mps2")
            if a is None:
                raise UserError("chain: recuperation_by_decel_mps2 needs the acceleration (signal accel_mps2)")
            a = np.abs(np.asarray(a, float))
            rec = rec * np.exp(-self.recuperation_by_decel_mps2 / np.where(a > 0, a, np.inf))
        aux = (self.auxiliary(n, signals) if self.predicts == "battery" else np.zeros(n))
        if self.predicts == "battery" and self.standstill_aux_w:
            aux = aux + self.standstill_aux_w * (v < STANDSTILL_MPS)
        return {"traction_w": trac, "recuperated_w": rec, "auxiliary_w": aux,
                "friction_brake_w": neg - rec_mech, "power_w": trac + rec + aux}

    def engine_on(self, p, v) -> np.ndarray:
        """Engine fuelled: when P > P_off or v > v_on, but not in overrun (moving, P < P_cut)."""
        on = np.asarray(p, float) > self.engine_off_below_w
        if self.engine_on_above_mps is not None:
            on |= np.asarray(v, float) > self.engine_on_above_mps
        if self.fuel_cut_below_w is not None:
            on &= ~((np.asarray(p, float) < self.fuel_cut_below_w) & (np.asarray(v, float) > STANDSTILL_MPS))
        return on

    def paid(self, p, v) -> np.ndarray:
        """Where the engine output demand costs fuel: where the engine is fuelled, or
        everywhere for a ``charge_sustaining`` chain (the battery's energy paid back)."""
        return self.engine_on(p, v) | self.charge_sustaining

    def _plug_in(self, p, v, n, signals, dt_s, trip, stored_j, spent_j) -> dict:
        bat, dt = self.depleting.chain.evaluate(p, v, signals=signals), _durations(dt_s, self.where)
        share, spent = on_battery(bat["power_w"] * dt, self.depleting.usable_j, spent_j, trip)
        before = np.r_[0.0, spent[:-1]] * ~_starts(trip, n) if spent_j is None else spent_j
        return plug_in(self.depleting, self._fuel(p, v, n, signals, dt_s, trip, stored_j, share == 0), bat, share,
                       spent, before, np.broadcast_to(np.asarray(dt, float), p.shape))

    def _fuel(self, p, v, n, signals, dt_s=None, trip=None, stored_j=None, sustaining=None) -> dict:
        on, extra, eta_t = self.engine_on(p, v), {}, _eval(self.traction_efficiency, v, p)  # (:meth:`paid`: on | cs)
        e = engine_demand(self, p, v, signals, eta_t)  # (model/chain_values.py: the one engine formula)
        eng, over = e.delivered_w, e.beyond_w
        pf = np.where(on, e.zero_output_w, 0.0) + np.where(on | self.charge_sustaining, eng / self.marginal_efficiency, 0.0)
        if self.recuperation_round_trip:  # a charge-sustaining hybrid's braking energy, given back
            lim = np.inf if self.recuperation_limit_w is None else self.recuperation_limit_w
            if self.battery_usable_j is None:
                pf = pf + (self.recuperation_round_trip * np.maximum(np.minimum(p, 0.0), -lim)
                           / eta_t / self.marginal_efficiency)
            else:  # only what the battery's window holds (model/chain_buffer.py)
                back, stored = buffered_return(p if sustaining is None else np.where(sustaining, p, 0.0), dt_s,
                                               self.recuperation_round_trip, lim, self.battery_usable_j,
                                               stored_j, trip, self.where)
                pf = pf - back / eta_t / self.marginal_efficiency
                extra = {"given_back_w": back, "stored_j": stored}
        if self.running_fuel_per_k:
            pf = pf * self.running_factor(n, signals)
        fp = self.fuel_props
        kgps = pf / fp["lhv_j_per_kg"]
        return {"engine_on": on, "engine_w": np.where(on, eng, 0.0), "power_w": pf,
                "fuel_lps": kgps / fp["density_kg_per_l"], "co2_kgps": kgps * fp["co2_kg_per_kg"],
                **extra, **({} if over is None else {"over_engine_w": over})}

    def running_factor(self, n: int, signals: dict | None = None) -> np.ndarray:
        """1 + r · max(T_ref − T, 0) per sample (``running_fuel_per_k``); 1 where the air
        temperature is unknown (no column, NaN)."""
        t = np.asarray((signals or {}).get(self.temperature_column, np.nan), float)
        t = t if t.shape == (n,) else np.broadcast_to(t, (n,))
        d = np.where(np.isfinite(t), np.maximum(self.cold_start_ref_c - t, 0.0), 0.0)
        return 1.0 + self.running_fuel_per_k * d

    def cold_start(self, air_c: float | None = None) -> dict:
        """The extra energy of one cold start at air temperature ``air_c`` [°C]: for a fuel
        chain ``fuel_l`` [L], ``fuel_j`` [J, LHV], ``co2_kg`` [kg] (None: at the reference
        ``cold_start_ref_c``); for a battery chain with ``[chain.hvac] warmup_j_per_k``,
        ``battery_j`` [J] = warmup · max(T_set − T, 0), the cabin's warm-up (None or an unknown
        temperature: none). Zeros where the chain has none."""
        if self.predicts == "battery" and self.hvac and self.hvac.get("warmup_j_per_k"):
            t = np.nan if air_c is None else float(air_c)
            dt = max(float(self.hvac.get("setpoint_c", 20.0)) - t, 0.0) if np.isfinite(t) else 0.0
            return {"fuel_l": 0.0, "fuel_j": 0.0, "co2_kg": 0.0,
                    "battery_j": float(self.hvac["warmup_j_per_k"]) * dt}
        if self.predicts != "fuel" or not (self.cold_start_fuel_l or self.cold_start_fuel_l_per_k):
            return {"fuel_l": 0.0, "fuel_j": 0.0, "co2_kg": 0.0, "battery_j": 0.0}
        litres = self.cold_start_fuel_l
        if air_c is not None and np.isfinite(air_c):
            litres += self.cold_start_fuel_l_per_k * max(self.cold_start_ref_c - float(air_c), 0.0)
        fp = self.fuel_props
        kg = litres * fp["density_kg_per_l"]
        return {"fuel_l": float(litres), "fuel_j": kg * fp["lhv_j_per_kg"],
                "co2_kg": kg * fp["co2_kg_per_kg"], "battery_j": 0.0}

    @property
    def battery_fuel_factor(self) -> float:
        """Fuel energy per unit of battery energy k [-] (default 1/η_m)."""
        return (self.battery_to_fuel if self.battery_to_fuel is not None
                else 1.0 / self.marginal_efficiency)

    # ------------------------------------------------------------------ TOML
    def to_dict(self) -> dict:
        """The ``[chain]`` table of this chain."""
        d: dict = {"predicts": self.predicts}
        if self.predicts == "wheel":
            return d
        if self.motor is not None:  # its motor, loss map and battery in place of η_t, η_r
            d["motor"] = {**self.motor.to_dict(), "aux_power_w": float(self.aux_power_w)}
        for k in () if self.motor is not None else ("traction_efficiency",) + (
                ("recuperation_efficiency",) if self.predicts != "fuel" else ()):
            val = getattr(self, k)
            d[k] = val.to_dict() if isinstance(val, Table) else float(val)
        if (self.predicts != "fuel" or self.recuperation_round_trip) and self.recuperation_limit_w is not None:
            d["recuperation_limit_w"] = float(self.recuperation_limit_w)
        if self.predicts != "fuel" and self.recuperation_by_decel_mps2:
            d["recuperation_by_decel_mps2"] = float(self.recuperation_by_decel_mps2)
        if self.predicts in ("battery", "fuel"):
            d["aux_power_w"] = float(self.aux_power_w)
            if self.predicts == "battery" and self.standstill_aux_w:
                d["standstill_aux_w"] = float(self.standstill_aux_w)
            if self.loads:
                d["loads"] = {k: float(g) for k, g in self.loads.items()}
            if self.hvac:
                d["hvac"] = dict(self.hvac)
        if self.predicts == "fuel":
            d.update(idle_fuel_power_w=float(self.idle_fuel_power_w),
                     marginal_efficiency=float(self.marginal_efficiency),
                     engine_off_below_w=float(self.engine_off_below_w), fuel=self.fuel)
            for k in ("engine_on_above_mps", "fuel_cut_below_w", "moving_idle_fuel_power_w", "engine_max_w"):
                if getattr(self, k) is not None:
                    d[k] = float(getattr(self, k))
            if self.charge_sustaining:
                d["charge_sustaining"] = True
            if self.recuperation_round_trip:
                d["recuperation_round_trip"] = float(self.recuperation_round_trip)
            if self.battery_usable_j is not None:
                d["battery_usable_j"] = float(self.battery_usable_j)
            if self.depleting is not None:
                d["depleting"] = self.depleting.to_dict()
            if self.battery_to_fuel is not None:
                d["battery_to_fuel"] = float(self.battery_to_fuel)
            if self.cold_start_fuel_l or self.cold_start_fuel_l_per_k:
                d["cold_start_fuel_l"] = float(self.cold_start_fuel_l)
            if self.cold_start_fuel_l_per_k:
                d["cold_start_fuel_l_per_k"] = float(self.cold_start_fuel_l_per_k)
            if self.running_fuel_per_k:
                d["running_fuel_per_k"] = float(self.running_fuel_per_k)
            if self.cold_start_fuel_l_per_k or self.running_fuel_per_k:
                d["cold_start_ref_c"] = float(self.cold_start_ref_c)
        for k in ("std_err", "reading", "provenance", "metrics"):
            if getattr(self, k):
                d[k] = getattr(self, k)
        return d


def _eval(eff: Efficiency, v, p) -> np.ndarray | float:
    return eff(v, p) if isinstance(eff, Table) else eff


def _signal(sig: dict, col: str, n: int, missing: float = 0.0) -> np.ndarray:
    """Column ``col`` of ``sig`` as n floats; NaN (unknown) reads as ``missing``."""
    if col not in sig:
        raise UserError(f"energy chain needs the log column '{col}', which the data do not have "
                        f"(available: {', '.join(sorted(sig)) or 'none'})")
    x = np.asarray(sig[col], float)
    x = x if x.shape == (n,) else np.broadcast_to(x, (n,))
    return np.where(np.isfinite(x), x, missing)
