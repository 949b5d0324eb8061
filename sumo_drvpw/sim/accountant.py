"""The plug-in inside a user's own TraCI/libsumo script: ``Accountant`` and ``RunResult``.

    import libsumo as conn                       # or a traci connection
    from sumo_drvpw.sim import Accountant

    conn.start(["sumo", "-c", "city.sumocfg"])
    acc = Accountant(conn, equations=["vsp_ldv1999", "drvpw_prius3"])
    conn.addStepListener(acc)                    # books every step after simulationStep()
    while conn.simulation.getMinExpectedNumber() > 0:
        conn.simulationStep()
        e = acc.energy("veh0")                   # energies so far [J] per equation and term
    result = acc.result()                        # RunResult: .vehicles, .edges, .classes, .summary
    result.write("out")                          # what `sumo-drvpw run` writes, as one output set
    conn.close()

Masses, vClasses and equations per vType are resolved as in ``run``
(:class:`sumo_drvpw.sim.run.VTypeResolver`); options (wind, air, slopes, road classes,
outputs) come from a scenario file when given (``scenario=``), else the defaults of
:mod:`sumo_drvpw.sim.scenario`. Step one step at a time (``simulationStep()`` without a
target time): a listener is called once per call, so a call that jumps several steps
cannot be booked step by step; such jumps are counted in ``summary["missed_steps"]``.

Memory is bounded: vehicles that left the simulation are written out in batches
(:mod:`sumo_drvpw.sim.spill`) and ``energy(id)`` of one already written out raises
``KeyError`` saying so (``keep_vehicles=True`` keeps every vehicle, as before).
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

from sumo_drvpw.errors import UserError
from sumo_drvpw.sim.chain_charge import DepartureCharges
from sumo_drvpw.sim.chain_outputs import chain_warnings
from sumo_drvpw.sim.ledger import LEDGER_CATEGORIES, EquationSet, Ledger
from sumo_drvpw.sim.loop import Physics, Stepper
from sumo_drvpw.sim.network import load_network
from sumo_drvpw.sim.outputs import RunResult, summary_dict
from sumo_drvpw.sim.resolver import (booked_as_warning, calibration_mass_warning, carrier_warning,
                                     fixed_mass_listing, fixed_mass_warning, untold_copies_warning)
from sumo_drvpw.sim.powertrain import no_hybrid_chain_warning
from sumo_drvpw.sim.trace import TraceWriter
from sumo_drvpw.sim.scenario import Scenario, cold_start_shares, load_scenario, resolve_equation
from sumo_drvpw.sim.scenario_paths import sumo_file_list
from sumo_drvpw.sim.sumo_outputs import device_inputs
from sumo_drvpw.sim.sumo_start import NewRun, scenario_option
from sumo_drvpw.sim.vtype_energy import expand as expand_vtype_energy, listing_warning
from sumo_drvpw.sim.vtypes import GENERIC_VCLASSES, default_mass_warnings, read_vtypes

__all__ = ["Accountant", "RunResult"]

try:  # traci and libsumo accept only subclasses of traci.StepListener as listeners
    from traci import StepListener as _Listener
except ImportError:  # pragma: no cover - traci ships with every SUMO Python install
    _Listener = object

#: share of a run's vehicle-steps outside the range an equation's chain was fitted on
#: (driving power, speed; Equation.validity) above which the run warns
OUT_OF_RANGE_WARN = 0.05
#: How a step is booked (summary.json ``energy_booking``; docs/scenario.md).
ENERGY_BOOKING = ("acc term: coefficient × m·v̄·a with v̄ = (v_t + v_t−1)/2, i.e. the "
                  "kinetic-energy change ½m(v_t² − v_t−1²)/Δt, conserved at any step "
                  "length; "
                  "other terms at the speed of the distance SUMO moved the car in the step "
                  "(Euler update: v_t; ballistic: v̄)")


def _option(conn, key: str) -> str:
    """SUMO's value of option ``key`` ("" when the connection cannot say)."""
    try:
        return str(conn.simulation.getOption(key)).strip()
    except Exception:  # a fake connection, an FCD replay or an old SUMO
        return ""


def _option_files(conn, key: str) -> list[Path]:
    return [Path(f) for f in sumo_file_list(_option(conn, key))]


def scenario_for(conn, equations, scenario=None, **overrides) -> Scenario:
    """The scenario of an Accountant: a file or parsed :class:`Scenario` (its equations
    replaced by ``equations`` when given), or defaults around SUMO's own net file (no
    equations given: every vehicle by its class's built-in equations, as a bare SUMO config
    is run). Overrides that start or step SUMO — which the user's script does — are refused."""
    stepping = sorted(set(overrides) & {"begin", "end", "step_length", "connection", "gui", "options"})
    if stepping:
        raise UserError(f"Accountant: {', '.join(stepping)} start or step SUMO, which your script does (give "
                        "them to libsumo.start / traci.start, and step as far as you want); the Accountant books "
                        "the steps it is given")
    loop = sorted(set(overrides) & {"trace", "progress"})
    if loop:  # (a run's: the Accountant writes a trace where trace_path says, and draws no bar)
        raise UserError(f"Accountant: {', '.join(loop)} are a run's settings: give trace_path=... for a trace; "
                        "your loop shows its own progress")
    if isinstance(scenario, Scenario):
        if equations is None:
            return scenario
        import dataclasses

        return dataclasses.replace(scenario, equations=[
            resolve_equation(e, scenario.path.parent if scenario.path else None, "Accountant")
            for e in equations])
    if scenario is not None:
        if equations is not None:
            overrides["equations"] = list(equations)
        from sumo_drvpw.sim.scenario_paths import scenario_path

        return load_scenario(scenario_path(scenario), **overrides)  # (a built-in's name too, as run takes it)
    if equations is None:
        from sumo_drvpw.sim.scenario import CONFIG_EQUATIONS

        equations = list(CONFIG_EQUATIONS)
    nets = _option_files(conn, "net-file")
    if not nets:
        raise UserError("Accountant: SUMO does not say its net-file (getOption): is it started "
                        "(libsumo.start / traci.start) before the Accountant? Else give "
                        "scenario=... with [sumo] net")
    doc = {"equations": list(equations), "sumo": {"net": str(nets[0])}}
    return load_scenario(doc=doc, **overrides)


class Accountant(_Listener):
    """Books driving power and energy per term for every vehicle of a running simulation.

    Parameters
    ----------
    conn : the ``libsumo`` module or a ``traci`` connection, already started
    equations : built-in names, TOML paths or :class:`Equation` objects (default: the
        scenario's; without a scenario, each vehicle's class's built-in equations and the
        chain of the carrier its emissionClass names, as a bare SUMO config is run)
    scenario : optional scenario TOML (or parsed :class:`Scenario`) for the options
    trace_path : optional path of a per vehicle-step ``trace.parquet``
    keep_vehicles : keep every vehicle's row in memory for the whole run (the old,
        unbounded way); by default vehicles that left the simulation are written out in
        batches of ``flush_vehicles`` (:mod:`sumo_drvpw.sim.spill`) into ``spill_dir``
        (default: a temporary folder) and memory holds the running vehicles only
    net : the scenario's network (:func:`~sumo_drvpw.sim.network.load_network`), when
        already loaded (default: loaded from the scenario)
    vtypes : the route files' vTypes (:func:`~sumo_drvpw.sim.vtypes.read_vtypes`), when
        already read (default: read from the scenario's route files, else SUMO's options)
    overrides : scenario values to replace (see ``sumo_drvpw.sim.scenario.OVERRIDES``), but
        those that start or step SUMO (begin, end, step_length, connection, gui, options):
        the user's script does that

    Use it as a step listener (``conn.addStepListener(acc)``) or call :meth:`step` after
    each ``simulationStep()`` yourself.
    """

    def __init__(self, conn, equations=None, scenario=None, trace_path=None,
                 keep_vehicles: bool = False, spill_dir=None, flush_vehicles: int | None = None,
                 net=None, vtypes=None, **overrides):
        from sumo_drvpw.sim.resolver import VTypeResolver

        self._t0 = time.perf_counter()
        self.conn = conn
        if _option(conn, "mesosim").lower() == "true":
            raise UserError("Accountant: SUMO runs mesoscopic (option mesosim true): it moves vehicles queue by "
                            "queue, without lanes or accelerations, so no driving power follows from it; run "
                            "SUMO microscopically")
        self.left_new_run: tuple[float, float] | None = None  # (last booked time, new time)
        if isinstance(equations, (str, Path)) or hasattr(equations, "terms"):
            equations = [equations]  # one equation, not a list of them (a str: not its letters)
        sc = self.scenario = scenario_for(conn, equations, scenario, **overrides)
        files = list(sc.route_files) or (_option_files(conn, "route-files")
                                          + _option_files(conn, "additional-files"))
        self.file_vtypes = (vtypes if vtypes is not None   # already read by the caller
                            else read_vtypes([f for f in files if f.is_file()]))
        self.equations = list(sc.equations)
        names = [e.name for e in self.equations]
        for vid, info in list(self.file_vtypes.items()):  # vTypes naming an equation the scenario lacks
            if info.equation and info.equation not in names:
                if sc.vtype_filter is not None and info.id not in sc.vtype_filter:
                    continue
                eq = resolve_equation(info.equation, Path(info.source).parent,
                                      f"{info.source}: vType '{info.id}' drvpw.equation")
                if eq.name != info.equation:
                    if not _names_a_file(info.equation):
                        raise UserError(f"{info.source}: vType '{info.id}' names equation "
                                        f"'{info.equation}', whose name is '{eq.name}'")
                    # an equation file named by its path (as export-vtype writes it): the vType
                    # books by the equation the file holds
                    self.file_vtypes[vid] = dataclasses.replace(info, equation=eq.name)
                if eq.name not in names:
                    self.equations.append(eq)
                    names.append(eq.name)
        # vtype_energy: the vTypes' own Energy-model parameters, one equation per vType
        # (SUMO books its radial drag per step: a replay's recording's step, not its rows' interval)
        self.equations, self.vtype_energy = expand_vtype_energy(
            self.equations, self.file_vtypes, sc,
            getattr(conn, "recorded_step_s", None) or float(conn.simulation.getDeltaT()))
        self.names = names = [e.name for e in self.equations]
        if net is not None and not hasattr(net, "edge_ids"):
            raise UserError(f"Accountant: net must be a loaded network (sumo_drvpw.sim.network.load_network), "
                            f"got {type(net).__name__} {str(net)[:60]!r}; a net file goes in the scenario "
                            "([sumo] net), or SUMO's own is read")
        self.net = net if net is not None else load_network(
            sc.net_file, sc.road_class, sc.slope_window, sc.slope_max)
        self.eqset = EquationSet(self.equations)
        self.ledger = Ledger(len(self.net.edge_ids), len(self.equations))
        if not keep_vehicles:
            from sumo_drvpw.sim.spill import VehicleSpill

            self.ledger.spill = VehicleSpill(names, [e.predicts for e in self.equations],
                                             spill_dir)
            if flush_vehicles is not None:
                if flush_vehicles < 1:
                    raise UserError(f"Accountant: flush_vehicles must be ≥ 1, got {flush_vehicles}")
                self.ledger.flush_vehicles = int(flush_vehicles)
        self.physics = Physics(wind_speed=sc.wind_speed, wind_from_deg=sc.wind_from_deg,
                               rho=sc.rho, ambient_c=sc.air_temperature_c,
                               cold_start=float(getattr(sc, "cold_start", 0.0)),
                               cold_start_vtypes={  # the scenario's win over the vTypes' params
                                   **{vt: i.cold_start for vt, i in self.file_vtypes.items()
                                      if i.cold_start is not None},
                                   **cold_start_shares(getattr(sc, "vtype_data", {}))},
                               cold_start_vclasses=cold_start_shares(getattr(sc, "vclass_data", {})),
                               cold_start_vehicles=getattr(self.file_vtypes, "vehicle_cold_start", None),
                               cold_start_flows=getattr(self.file_vtypes, "flow_cold_start", None),
                               slope_tol=sc.slope_tol,
                               slope_reference=sc.slope_reference,
                               acceleration=sc.acceleration, heading=sc.wind_heading,
                               positions=sc.positions,
                               transportable_mass=sc.transportable_mass,
                               # a replay's own options say how its recording moved
                               ballistic_given=None if getattr(conn, "is_replay", False)
                               else scenario_option(sc, "step-method.ballistic"))
        self.resolver = VTypeResolver(sc, self.file_vtypes, self.equations, conn)
        self.trace = None
        if trace_path is not None:
            self.trace = TraceWriter(Path(trace_path), self.ledger, names, self.net.edge_ids)
        use_subs = getattr(conn, "__name__", "") != "libsumo" and hasattr(conn, "getLabel")
        self.stepper = Stepper(conn, self.net, self.eqset, self.ledger, self.physics,
                               self.resolver, self.trace, use_subscriptions=use_subs)
        if self.ledger.chain is not None:  # a plug-in hybrid's declared charge at departure (sim/chain_charge.py)
            fv, sw = self.file_vtypes, _where_of(sc)
            self.ledger.chain.charges = DepartureCharges.of_files(fv, {
                vt: (d["battery_charge_wh"], sw) for vt, d in getattr(sc, "vtype_data", {}).items()
                if "battery_charge_wh" in d}) or None
        if getattr(conn, "is_replay", False):  # containers' mass read too (a replay: from their rows)
            self.stepper.riders.box_of = conn.box_of
        elif getattr(self.file_vtypes, "containers", 0):
            self.stepper.riders.box_of = self.file_vtypes.container_of
        # a run that resumes a saved state (load-state): its first step's vehicles are not booked again
        self.stepper.resumed = (sc is not None and scenario_option(sc, "load-state") is not None) \
            or bool(_option_files(conn, "load-state"))  # (started so by the user's script)
        self.begin = float(conn.simulation.getTime())
        self.interrupted = False

    # -- the step listener protocol (traci.StepListener) ---------------------------------
    def step(self, t=0) -> bool:
        """Book the step SUMO just made; returns True (stay active). A step of a new run —
        time went back: a load(), or a libsumo session started after this one's close
        (libsumo keeps its step listeners across close and start) — ends the booking: as a
        step listener the Accountant leaves (returns False; its result says so), called by
        hand it raises (:class:`~sumo_drvpw.sim.sumo_start.NewRun`, a UserError)."""
        try:
            self.stepper.after_step()
        except NewRun as e:
            if getattr(self, "_ID", None) is None:  # not a step listener: the script's error
                raise
            self.left_new_run = (e.last_t, e.t_now)
            return False
        except Exception as e:  # SUMO closed under it: traci's FatalTraCIError, libsumo's error
            if type(e).__name__ in ("FatalTraCIError", "TraCIException") and self.stepper.last_t is not None \
                    and not _connected(self.conn):
                raise UserError("Accountant: SUMO is closed (or not started): step() books the step SUMO "
                                "just made; its result() stays readable") from None
            raise
        return True

    def cleanUp(self) -> None:  # noqa: N802 (traci's name)
        pass

    # -- reading while the simulation runs ----------------------------------------------
    def energy(self, vehicle_id: str) -> dict[str, dict[str, float]]:
        """Energies of a vehicle so far [J]: equation → {acc, grade, aero, roll, other
        (net per term), traction, recuperable, net — the driving energy —, teleports,
        teleport_kinetic, teleport_potential: the energy jumps of the teleports it ended,
        apart from driving, sim/teleport.py}; only equations that apply to it. An
        equation with an energy chain adds ``"chain"``: {traction_j, recuperated_j,
        auxiliary_j, net_j [J at the battery] or fuel_j [J], fuel_l [L], co2_kg [kg]}."""
        i = self.stepper.vmap.get(vehicle_id)
        if i is None:
            if self.ledger.flushed_vehicles:
                raise KeyError(f"vehicle '{vehicle_id}' is not in the Accountant's memory: "
                               "never seen, or it left the simulation and its totals were "
                               "written out (result().vehicles has them)")
            raise KeyError(f"vehicle '{vehicle_id}' has not been seen by the Accountant")
        led = self.ledger
        out = {}
        for e, name in enumerate(self.names):
            if not led.veh_keep[i] or not led.veh_app_seen[i, e]:  # (applied at some time of its trip)
                continue
            tr, rc = led.veh_trac[i, e], led.veh_recup[i, e]
            d = {c: float(tr[k] + rc[k]) for k, c in enumerate(LEDGER_CATEGORIES)}
            d.update(traction=float(tr.sum()), recuperable=float(rc.sum()),
                     net=float(tr.sum() + rc.sum()), teleports=int(led.veh_teleports[i]),
                     teleport_kinetic=float(led.veh_tele[i, e, 0]),
                     teleport_potential=float(led.veh_tele[i, e, 1]))
            out[name] = d
        chain = getattr(led, "chain", None)
        if chain is not None:
            for name, q in chain.vehicle(i).items():
                if name in out:
                    out[name]["chain"] = q
        return out

    def set_cold_start(self, vehicle_id: str, share) -> None:
        """Say that vehicle ``vehicle_id`` (e.g. one this script adds with
        ``vehicle.add``) starts cold with this share (True/False or 0–1): from its departure
        the energy chains book ``share`` × their cold start as it decays, as for a route file's
        ``drvpw.cold_start`` param, which this overrides. Call it before the vehicle departs.
        ValueError when the share is not one, the vehicle has departed already, or no
        equation of the run books fuel or battery energy."""
        if isinstance(share, bool):
            share = 1.0 if share else 0.0
        try:
            share = float(share)
        except (TypeError, ValueError):
            share = float("nan")
        if not 0.0 <= share <= 1.0:
            raise ValueError(f"set_cold_start: the share must be true, false or 0–1, got {share!r}")
        chain = getattr(self.ledger, "chain", None)
        if chain is None:
            raise ValueError("set_cold_start: no equation of this run books fuel or battery energy (no energy chain)")
        if vehicle_id in self.stepper.vmap:
            raise ValueError(f"set_cold_start: vehicle '{vehicle_id}' has departed already; its departure booked its "
                             "cold start (say it before it departs)")
        chain.set_vehicle_share(vehicle_id, share)

    def set_battery_charge(self, vehicle_id: str, charge_wh) -> None:
        """Say that vehicle ``vehicle_id`` (e.g. one this script adds with ``vehicle.add``)
        departs with ``charge_wh`` [Wh] of a plug-in hybrid chain's usable energy left, as a
        route file's ``device.battery.chargeLevel`` param (sim/chain_charge.py); this overrides
        whatever the route files (its vType's ``actualBatteryCapacity`` too) or the scenario say. Call it before the vehicle departs. ValueError when the charge is not a number
        ≥ 0, the vehicle has departed already, or no equation of the run has a plug-in hybrid's
        battery; a charge above the usable energy of a chain that books it is refused at its
        departure."""
        from sumo_drvpw.sim.chain_charge import CHARGE_LEVEL, _charge_wh

        try:
            wh = _charge_wh(charge_wh, CHARGE_LEVEL, "set_battery_charge")
        except UserError as e:
            raise ValueError(str(e)) from None
        chain = getattr(self.ledger, "chain", None)
        if chain is None or not any(chain.plug_in(e) for e in chain.active):
            raise ValueError("set_battery_charge: no equation of this run has a plug-in hybrid's battery ([chain.depleting])")
        if vehicle_id in self.stepper.vmap:
            raise ValueError(f"set_battery_charge: vehicle '{vehicle_id}' has departed already (say it before it departs)")
        chain.charges = chain.charges or DepartureCharges()
        chain.charges.told[str(vehicle_id)] = wh

    # -- the end --------------------------------------------------------------------------
    def close_trace(self) -> None:
        if self.trace is not None:
            self.trace.close()
            self.trace = None

    def _vtype_energy_listing(self) -> dict:
        """summary.json assumptions.vtype_energy, with ``also_booked_by`` (resolver.also_booked)."""
        also = dict(sorted(self.resolver.also_booked.items()))
        return {**self.vtype_energy, "also_booked_by": also} if also else self.vtype_energy

    def result(self, extra: dict | None = None) -> RunResult:
        """Everything booked so far as a :class:`RunResult` (tables, summary, writer)."""
        self.close_trace()
        sc, led, net, st = self.scenario, self.ledger, self.net, self.stepper
        # the last step it booked (SUMO may have stepped on: a listener removed, a new session)
        end = float(st.last_t) if st.last_t is not None else st.now()  # (none booked: a merged replay's end)
        summary_extra = {
            "scenario": str(sc.path) if sc.path else None, "begin_s": self.begin,
            "end_s": end, "step_length_s": st.dt, "step_method": st.step_method,
            "missed_steps": st.missed_steps, "energy_booking": ENERGY_BOOKING,
            "vtype_changes": st.retyped,
            "shut_off_at_long_stops": st.shutoff.summary() if st.shutoff is not None else None,
            "parking": st.parking.summary() if st.parking.on else None,
            "network": network_info(net, led), "interrupted": self.interrupted,
            "wall_time_s": time.perf_counter() - self._t0, "connection": sc.connection,
            "air_density_kgm3": sc.rho, "slope_reference": sc.slope_reference,
            "acceleration_source": sc.acceleration, "position_source": sc.positions,
            "wind": {"speed_mps": sc.wind_speed, "from_deg": sc.wind_from_deg,
                     "heading_source": sc.wind_heading},
            "equation_sources": {e.name: (e.path or "<object>") for e in self.equations},
            "skipped": {k: dict(sorted(v.items())) for k, v in self.resolver.skipped.items()},
            "excluded_by_vehicles_vtypes": self.resolver.excluded,
            "vehicles_in_memory_peak": int(led.peak_held),
            "assumptions": {"default_masses": dict(sorted(self.resolver.assumptions.items())),
                            "sumo_masses": dict(sorted(self.resolver.sumo_masses.items())),
                            "booked_as": dict(sorted(self.resolver.booked_as.items())),
                            "energy_carrier": dict(sorted(self.resolver.carriers.items())),
                            "powertrain": dict(sorted(self.resolver.powertrains.items())),
                            "calibration_mass": dict(sorted(self.resolver.mass_far.items())),
                            "calibration_mass_fixed": fixed_mass_listing(self.resolver.fixed_far),
                            "untold_copy_masses": dict(sorted(self.resolver.untold_copies.items())),
                            "told_copy_masses": dict(sorted(self.resolver.told_copies.items())),
                            "vtype_energy": self._vtype_energy_listing()},
        }
        summary_extra.update(extra or {})
        warnings = network_warnings(net) + road_class_warnings(sc.road_class, net)
        rd = st.reader
        if rd.subs and rd.fallback_reads > max(100, 0.01 * led.samples):  # traci: one call per getter
            warnings.append(f"{rd.fallback_reads} vehicle-steps were missing from the plug-in's traci "
                            "context subscription and were read by getters, a call each (slow): did the "
                            "script change the simulation domain's context subscription (subscribeContext "
                            "or unsubscribeContext on traci.simulation)?")
        warnings += default_mass_warnings(self.resolver.assumptions)
        if led.hard_brakes:
            warnings.append(f"{led.hard_brakes} vehicle-step(s) decelerated beyond any brake (up to "
                            f"{led.hard_brake_max_mps2:.0f} m/s², over 1.2 g: SUMO's emergency braking, e.g. a "
                            "train stopped at a red signal within one step): their energy at the wheels is "
                            "booked, but no battery or fuel chain recuperates it (friction brakes) "
                            "(summary.json hard_brakes)")
        unused = sorted(set(getattr(sc, "vtype_data", {})) - set(self.resolver.cache) - self.resolver.seen)
        if unused:  # a typo, or a vTypeDistribution's id (its vehicles have the members' vTypes)
            warnings.append(f"{sc.path or 'the scenario'}: " + ", ".join(f"[vtypes.{v}]" for v in unused)
                            + " matched no vehicle's vType in this run, so its settings were not used "
                            "(a vTypeDistribution's vehicles take its members' vType ids)")
        if self.resolver.sumo_masses:
            warnings.append("vTypes in none of the route/additional files read took SUMO's mass "
                            "(made by TraCI, or loaded through options the plug-in does not read; "
                            "SUMO's default unless the vType gives one): " + ", ".join(
                                f"{vt} ({a['vclass']}, {a['mass_kg']:g} kg)"
                                for vt, a in sorted(self.resolver.sumo_masses.items()))
                            + " (summary.json assumptions.sumo_masses; set vtypes.<id>.mass_kg)")
        if self.resolver.booked_as:
            warnings.append(booked_as_warning(self.resolver.booked_as))
        for w in (no_hybrid_chain_warning(self.resolver.powertrains), calibration_mass_warning(self.resolver.mass_far),
                  fixed_mass_warning(self.resolver.fixed_far)):
            if w:
                warnings.append(w)
        if self.resolver.untold_copies or self.resolver.told_copies:
            warnings.append(untold_copies_warning(self.resolver.untold_copies, self.resolver.told_copies))
        vt_warning = listing_warning(self._vtype_energy_listing())
        if vt_warning:
            warnings.append(vt_warning)
        # persons (counted as pedestrians) are never booked: no warning for them
        skipped = {c: n for c, n in self.resolver.skipped["by_vclass"].items() if c != "pedestrian"}
        if skipped:
            generic = sorted(c for c in skipped if c in GENERIC_VCLASSES)
            warnings.append("vehicles of vClasses none of the run's equations is made for were not booked: "
                            + ", ".join(f"{c} {n}" for c, n in sorted(skipped.items()))
                            + (f" (vClass {', '.join(generic)} says what a vehicle may use, not "
                               "what it is, and their vTypes' emissionClass, guiShape and id name no "
                               f"vehicle: set vclasses.{generic[0]}.equations and mass_kg in a "
                               "scenario file)" if generic else ""))
        if not led.types_seen:  # (a vehicle left out, by its vClass or the scenario's vtypes, is seen)
            warnings.append(f"no vehicle was on the road between {self.begin:g} s and {end:g} s, so every "
                            "total is 0: the route files hold no vehicle departing in that window (check "
                            "their vehicles', trips' and flows' departure times against the run's begin "
                            "and end)")
        clipped = summary_extra["network"]["slope_clipped_lanes"]
        if clipped:
            warnings.append(f"{int(led.clipped)} vehicle-steps on slopes beyond "
                            f"±{sc.slope_max:g} rad were clipped (the rise cut off is spread over the "
                            "lane, so climbs stay exact); most on lanes "
                            + ", ".join(f"{k} ({n})" for k, n in list(clipped.items())[:3])
                            + " (summary.json network.slope_clipped_lanes)")
        if st.missed_steps and getattr(self.conn, "is_replay", False):
            warnings.append(f"{st.missed_steps} timesteps of {st.dt:g} s are missing between "
                            "the FCD's timesteps and were not booked (a gap in the recording, or "
                            "FCD written every n-th step: record it every step)")
        elif st.missed_steps:
            warnings.append(f"{st.missed_steps} simulation steps were not booked: call "
                            "simulationStep() without a target time")
        if (w := getattr(st.lane_numbers, "warning", lambda: None)()):
            warnings.append(w)
        if getattr(st, "repeated_steps", 0):
            warnings.append(f"{st.repeated_steps} calls to book a simulation step already booked (the same "
                            "time) were ignored: the accountant is stepped twice per step (added as a step "
                            "listener twice, or as one and called by the script too)")
        if self.left_new_run:
            warnings.append("a new run began (simulation time went back from {:g} s to {:g} s): this "
                            "Accountant stopped booking there and left the step listeners; "
                            "start a new one for the new run".format(*self.left_new_run))
        ecs = {vt: v.emission_class for vt, v in self.file_vtypes.items() if getattr(v, "emission_class", None)}
        warnings += chain_warnings(led.chain, led.chainless, led.chainless_vtypes, ecs)
        summary_extra["warnings"] = warnings + list(summary_extra.get("warnings", []))
        summary = summary_dict(led, net, self.names, self.eqset.uses_other, summary_extra,
                               self.file_vtypes)
        classes = list(net.classes)
        k = np.array([classes.index(c) for c in net.edge_class], np.int64)
        for e, eq in enumerate(self.equations):
            dist = np.bincount(k, weights=led.edge_dist_eq[:, e], minlength=len(classes))
            summary["equations"][eq.name]["distance_m"] = {
                c: float(d) for c, d in zip(classes, dist)}
            summary["equations"][eq.name].update({
                "predicts": eq.predicts, "vclasses": list(eq.vclasses),
                "speed_range_mps": list(eq.speed_range_mps) if eq.speed_range_mps else None,
                "accel_range_mps2": list(eq.accel_range_mps2) if eq.accel_range_mps2 else None,
                "out_of_range_samples": int(led.out_of_range[e])})
            for w in (getattr(eq.chain, "provenance", None) or {}).get("warnings", []) if any(
                    summary["equations"][eq.name]["distance_m"].values()) else ():  # (of what it booked)
                summary["warnings"].append(f"{eq.name}: its chain's calibration warned: {w}")
            vr, _, pr = eq.validity()  # a chain's fitted driving power (and speed) range
            if pr is not None:
                summary["equations"][eq.name].update(power_range_w=list(pr),
                                                     speed_range_mps=list(vr) if vr else None)
                speed = f" or speed {vr[0] * 3.6:.0f} … {vr[1] * 3.6:.0f} km/h" if vr else ""
                share = led.out_of_range[e] / max(summary.get("samples") or 0, 1)
                if share > OUT_OF_RANGE_WARN:
                    summary["warnings"].append(
                        f"{eq.name}: {share:.0%} of the vehicle-steps drove outside the driving power "
                        f"{pr[0] / 1000:.1f} … {pr[1] / 1000:.1f} kW{speed} (or acceleration) its energy chain was fitted on: its battery or fuel there is "
                        "extrapolated (summary.json out_of_range_samples)")
        # chains that booked nobody because every vType they were made for writes another
        # carrier (no news among the plug-in's own chains, one per carrier: the classes,
        # written or SUMO's defaults, choosing among them is what they are for)
        idle = [] if getattr(sc, "default_carrier", False) else [
            e.name for e in self.equations
            if not any(summary["equations"][e.name]["distance_m"].values())
            and any(e.name in c["not_booked_by"] for c in self.resolver.carriers.values() if c["from"] == "written")]
        by_carrier = self.resolver.skipped.get("by_carrier", {})
        if idle or by_carrier:
            summary["warnings"].append(carrier_warning(self.resolver.carriers, by_carrier, idle))
        result = RunResult(ledger=led, net=net, names=self.names,
                           predicts=[e.predicts for e in self.equations], summary=summary,
                           begin=self.begin, end=end, edgedata=sc.edgedata, figures=sc.figures,
                           difference=sc.difference, period=getattr(sc, "period", None))
        result.exported_vtypes, result.energy_masses = device_inputs(self.file_vtypes, self.resolver.assumptions)
        return result


def network_info(net, ledger, top: int = 10) -> dict:
    """The ``network`` block of summary.json: file, elevation, most-clipped lanes, and where the
    table was read from (``table``: the cache or the net file, and why it was not kept)."""
    counts = ledger.lane_clipped
    order = np.argsort(-counts, kind="stable")[:top] if len(counts) else []
    lanes = {net.lane_ids[i]: int(counts[i]) for i in order if counts[i] > 0} \
        if net.lane_ids is not None else {}
    return {"file": str(net.path), "has_elevation": bool(net.has_elevation),
            "z_share": float(net.z_share), "slope_clipped_lanes": lanes,
            **({"table": net.table_source} if getattr(net, "table_source", None) else {})}


#: a network whose lane shapes carry z on less than this share of their length is warned of:
#: its elevation is partial (bridges, a few OSM ele points), the rest is booked flat
PARTIAL_ELEVATION_SHARE = 0.5


def network_warnings(net) -> list[str]:
    """Warnings about the network a user should see (printed by the CLI)."""
    if net.has_elevation:
        if net.z_share >= PARTIAL_ELEVATION_SHARE:
            return []
        return [f"network {net.path.name} has elevation on only {100 * net.z_share:.2g} % of its "
                "lane length (z in a few lane shapes: bridges, a few OSM ele points): every other "
                "slope is 0, so the grade term books only those lanes; build it with elevation "
                "(netconvert --heightmap.geotiffs / OSM ele) for hilly areas"]
    return [f"network {net.path.name} has no elevation (no z in any lane shape): every slope "
            "is 0, so the grade term is 0; build it with elevation (netconvert "
            "--heightmap.geotiffs / OSM ele) for hilly areas"]


def road_class_warnings(rule, net) -> list[str]:
    """The road-class rule's edge types and edge ids that match nothing in the network (a typo
    there leaves its edges in city or highway, its class empty, without a word); a type
    matched exactly, so an OSM compound type ('cycleway.lane|highway.primary') is named."""
    types = set(net.edge_type)
    out = []
    for kind, keys, have in (("types", getattr(rule, "types", {}) or {}, types),
                             ("edges", getattr(rule, "edges", {}) or {}, set(net.edge_ids))):
        gone = sorted(k for k in keys if k not in have)
        if not gone:
            continue
        hint = ""
        if kind == "types":  # compound types holding the name: the likely intent
            near = sorted(t for t in types if any(g in t.split("|") for g in gone) and t not in keys)
            hint = (f"; the network's types holding it: {', '.join(near[:4])}{' …' if len(near) > 4 else ''}"
                    " (types match whole: list them too)") if near else ""
        out.append(f"road classes: {kind} {', '.join(map(repr, gone[:6]))}{' …' if len(gone) > 6 else ''} "
                   f"match no edge of {net.path.name}: their class books nothing{hint}")
    return out


def _names_a_file(value: str) -> bool:
    """Whether a vType's ``drvpw.equation`` value is an equation file's path (a TOML file, or
    a path with a folder), not an equation's name."""
    return value.lower().endswith(".toml") or "/" in value or "\\" in value


def _connected(conn) -> bool:
    """Whether SUMO answers on ``conn`` (a closed libsumo or traci connection does not)."""
    try:
        conn.simulation.getTime()
        return True
    except Exception:
        return False


def _where_of(sc) -> str:
    """The scenario's file, as its keys are named in a refusal."""
    return str(getattr(sc, "path", None) or "<scenario>")
