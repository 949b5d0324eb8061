"""Which equations book a vehicle, and at what mass: :class:`VTypeResolver`, asked once
per vType by the run (sim/run.py), an FCD replay (sim/fcd.py) and the Accountant: its
vClass and what vehicle it is (sim/vtypes.vehicle_body), the equations made for it, its
energy carrier and powertrain (a plug-in or full hybrid's or a conventional engine's fuel chain,
sim/powertrain.py), its mass.
"""

from __future__ import annotations

import re

import numpy as np

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.constants import MASS_MAX_KG
from sumo_drvpw.sim.scenario_values import tiny_file_masses, tiny_mass, written_mass
from sumo_drvpw.sim.vtype_energy import battery_switch, energy_vtype_of, own_energy, run_emission_class
from sumo_drvpw.sim.carrier import (SUMO_DEFAULT_EMISSION_CLASS, SUMO_DEFAULT_EMISSION_CLASS_OTHER, energy_carrier,
                                    equation_carrier, is_hybrid_chain)
from sumo_drvpw.sim.vtypes import CAR_VCLASSES, SHORT_CAR_M, SUMO_DEFAULT_VTYPES, VAN_MAX_MASS_KG
from sumo_drvpw.sim.powertrain import POWERTRAIN_ORDER, powertrain_of_class


#: ratio of a vType's mass to the mass an equation booking it was calibrated at (or the
#: reverse) from which the run says so: the mass-scaled terms (acc, grade, roll) follow the
#: vType, the aero term and what else the fit absorbed stay the calibration vehicle's
MASS_FAR = 1.5

#: an HBEFA 4 emissionClass naming its vehicles' gross weight band — ``RT_le7.5t``,
#: ``RT_gt7.5-12t``, ``UBus_Midi_le15t``, ``Coach_Std_le18t``, ``TT_AT_gt34-40t``,
#: ``RigidTruck_FCEV_le7_5t`` —: its upper limit [t], the most such a vehicle weighs laden
#: (SUMO 1.28 also ships ``TT_AT_28-34t_EE``, a band written without its ``gt``)
_WEIGHT_BAND = re.compile(r"(?:^|_)(?:le|lt)(\d+(?:[._]\d+)?)t(?=_|$)|(?:^|_)(?:gt)?\d+(?:[._]\d+)?-(\d+(?:[._]\d+)?)t(?=_|$)")


def class_mass_limit_kg(emission_class: str | None) -> float | None:
    """The gross weight [kg] an emissionClass's name bounds its vehicles by (``HBEFA4/
    RT_le7.5t_Euro-VI_A-C`` → 7500, ``HBEFA4/UBus_Std_gt15-18t_…`` → 18000), None when it
    names no upper limit (``RT_gt32t``, cars, motorcycles' cc)."""
    m = _WEIGHT_BAND.search((emission_class or "").split("/")[-1])
    return None if m is None else float((m.group(1) or m.group(2)).replace("_", ".")) * 1000.0


def calibration_mass_kg(eq) -> float | None:
    """The vehicle mass [kg] an equation's coefficients were calibrated at: a calibrated
    equation's ``metrics.reference_mass_kg``, else its ``equation.reference_mass_kg`` (the
    test mass of a published fit, a vehicle file's mass); None when it gives none."""
    m = (eq.metrics or {}).get("reference_mass_kg") or getattr(eq, "reference_mass_kg", None)
    return float(m) if m else None


class VTypeResolver:
    """vType id → (mass [kg], applicability per equation, accounted?, vClass) for the loop.

    vClass: SUMO's (``vehicletype.getVehicleClass``) > the vType's ``vClass`` attribute in
    the files > ``passenger`` (SUMO's default).
    Equations: scenario ``vtypes.<id>.equations`` > param ``drvpw.equation`` > scenario
    ``vclasses.<vClass>.equations`` > every equation whose ``vclasses`` contain the vClass.
    A vType of a generic vClass (``ignoring``, ``custom1``, ``custom2``:
    :data:`sumo_drvpw.sim.vtypes.GENERIC_VCLASSES`) that none of these gives an equation is
    booked as the road vehicle its ``emissionClass``, ``guiShape`` or id names; so is a vType
    of a light vClass whose written ``emissionClass`` names a heavy vehicle, or the reverse
    (a sedan in vClass bus for the bus lanes) unless the scenario or the vType names its
    equations (:func:`sumo_drvpw.sim.vtypes.vehicle_body`; that vehicle's class equations,
    ``vclasses.<that>`` settings and default mass), listed in :attr:`booked_as`.
    A vType with none is not accounted and counted in :attr:`skipped` (by vClass and vType).
    Energy carrier: unless the scenario or the vType names its equations, an equation whose
    chain books a fuel or the battery books only vehicles whose written emissionClass names
    that carrier or none (:func:`sumo_drvpw.sim.carrier.energy_carrier`): a petrol chain
    does not book an electric or a diesel car. A vType that writes none is booked by every
    chain made for its vClass (alternatives a user chose), except with the scenario's
    ``default_carrier`` (the plug-in's own equations) where chains of several carriers
    apply: then by SUMO's default emissionClass (petrol car, diesel van). The chains left
    out per vType are in :attr:`carriers`, vehicles with no equation left in
    :attr:`skipped` ``by_carrier``.
    Mass: scenario ``vtypes.<id>.mass_kg`` > param ``drvpw.mass`` > ``mass`` attribute (or
    SUMO's deprecated ``vehicleMass`` param) plus the ``loading`` param, written in the
    route/additional files > for a vType no file declares and no SUMO default type (made
    during a live run by TraCI), SUMO's ``vehicletype.getMass`` > scenario
    ``vclasses.<vClass>.mass_kg`` (plus loading) > the built-in default of the vClass
    (:data:`sumo_drvpw.sim.vtypes.DEFAULT_MASS_KG`, listed in :attr:`assumptions`) unless
    ``vehicles.default_masses = false``; none → UserError.
    """

    def __init__(self, scenario, file_vtypes: dict, equations: list, conn=None):
        self.sc, self.files, self.conn = scenario, file_vtypes, conn
        tiny_file_masses(file_vtypes, getattr(scenario, "vtype_data", None) or {})  # (riders' too)
        self.names = [e if isinstance(e, str) else e.name for e in equations]
        #: equation name → vClasses it is made for (names given as plain strings: any)
        self.vclasses = {(e if isinstance(e, str) else e.name):
                         (None if isinstance(e, str) else set(e.vclasses)) for e in equations}
        #: equation name → energy carrier its chain books (None: driving power only)
        self.carrier_of = {(e if isinstance(e, str) else e.name):
                           (None if isinstance(e, str) else equation_carrier(e)) for e in equations}
        #: fuel-chain equation → whether it is a hybrid's (sim/carrier.is_hybrid_chain)
        self.hybrid_of = {e.name: h for e in equations if not isinstance(e, str)
                          and (h := is_hybrid_chain(e)) is not None}
        #: fuel-chain equations of plug-in hybrids ([chain.depleting], model/chain_plugin.py)
        self.plug_in = {e.name for e in equations if not isinstance(e, str) and e.name in self.hybrid_of
                        and e.chain.depleting is not None}
        self.cache: dict[str, tuple] = {}
        #: equation → the vehicle mass its coefficients were calibrated at [kg] (a calibrated
        #: equation's metrics.reference_mass_kg, else its equation.reference_mass_kg: the test
        #: mass of a published fit; none at a fixed mass: it books every vType at it)
        self.calibrated_at = {e.name: float(m) for e in equations if not isinstance(e, str)
                              and e.mass_kg is None and (m := calibration_mass_kg(e))}
        #: vType → {"mass_kg", "calibrated_at_kg": {equation: kg}}: vTypes booked by equations
        #: calibrated at a mass :data:`MASS_FAR` times theirs or more, or as little
        self.mass_far: dict[str, dict] = {}
        #: equation → {"mass_kg", "calibrated_at_kg"}: equations that book every vType at a fixed
        #: mass_kg :data:`MASS_FAR` times the mass they were calibrated at or more, or as little
        #: (a [beta] equation read at its reference_mass_kg, a calibrated one given another mass_kg)
        self.fixed_far_eq = {e.name: {"mass_kg": float(e.mass_kg), "calibrated_at_kg": float(m)}
                             for e in equations if not isinstance(e, str) and e.mass_kg is not None
                             and (m := calibration_mass_kg(e)) and max(m / e.mass_kg, e.mass_kg / m) >= MASS_FAR}
        #: vType → {equation: its fixed_far_eq entry}: the vTypes such equations book
        self.fixed_far: dict[str, dict] = {}
        self.energy_of = energy_vtype_of(equations)  # vtype_energy equation → its vType
        self.energy_mass = {e.name: e.mass_kg for e in equations if getattr(e, "name", None) in self.energy_of}
        #: vTypes resolved by other resolvers of the same run (Dask buckets of an FCD replay),
        #: and vehicles' own copies booked at the scenario's [vtypes."<type>@<id>"] mass
        self.seen: set[str] = set()
        #: vType → (SUMO's mass when resolved, its loading) [kg]: live vTypes booked at a mass
        #: that follows SUMO's (not a scenario's mass_kg or a drvpw.mass), for a script's
        #: vehicletype.setMass during the run (:meth:`type_masses_changed`)
        self.watched: dict[str, tuple[float, float]] = {}
        #: a replay's vehicles' own vType copies (``<type>@<id>``: a script's setMass …) whose
        #: mass no [vtypes."<copy>"] mass_kg told: copy → its type, booked at that type's mass
        self.untold_copies: dict[str, str] = {}
        #: a replay's copies booked at the one mass their [vtypes."<copy>"] mass_kg tells: copy → kg
        self.told_copies: dict[str, float] = {}
        #: vehicles not accounted because no equation is made for their vClass (by_vclass,
        #: by_vtype) or none books their energy carrier (by_carrier, when any: vClass → count)
        self.skipped: dict[str, dict[str, int]] = {"by_vclass": {}, "by_vtype": {}}
        #: vType → {"emission_class", "from", "carrier", "not_booked_by"}: chain equations
        #: made for the vType's vClass that book another energy carrier
        self.carriers: dict[str, dict] = {}
        #: vType → its equations before its energy carrier chose among them (those made for
        #: its class; not for a vType whose equations are named): a vehicle's own copy with
        #: another emissionClass is booked from them (:meth:`own_copy`)
        self.made_for_app: dict[str, np.ndarray] = {}
        #: vType → {"emission_class", "from", "powertrain", "not_booked_by"}: fuel chains of
        #: its carrier made for another powertrain (a hybrid's or a conventional engine's)
        self.powertrains: dict[str, dict] = {}
        #: vehicles left out by ``vehicles.vtypes``
        self.excluded = 0
        #: vType → {"vclass", "mass_kg", "source"} for masses taken from class defaults
        self.assumptions: dict[str, dict] = {}
        #: vType → {"vclass", "mass_kg"}: vTypes in no file read, at SUMO's mass (made during
        #: the run by TraCI, or loaded through SUMO options the plug-in does not read)
        self.sumo_masses: dict[str, dict] = {}
        #: vtype_energy equation → the other battery chains that book its vType's vehicles
        #: too (alternatives, not more vehicles)
        self.also_booked: dict[str, list[str]] = {}
        #: vType → {"vclass", "booked_as", "from"}: vTypes booked as the vehicle their
        #: emissionClass, guiShape, id or length names, not by their vClass
        self.booked_as: dict[str, dict] = {}

    def _param(self, vt: str, key: str) -> str:
        if self.conn is None:
            return ""
        try:
            return self.conn.vehicletype.getParameter(vt, key) or ""
        except Exception:
            return ""

    def _sumo_mass(self, vt: str) -> float | None:
        """SUMO's mass of a vType no file declares (made by a TraCI script: a copy, a
        vehicle's own type after setMass), from a live run; None otherwise."""
        if self.conn is None or getattr(self.conn, "is_replay", False):
            return None
        try:
            m = float(self.conn.vehicletype.getMass(vt))
        except Exception:
            return None
        return m if m > 0 and np.isfinite(m) else None

    def _vclass(self, vt: str, info, default: str = "passenger") -> str:
        """SUMO's vClass of a vType, else the files', else that of SUMO's own type of this
        id (DEFAULT_BIKETYPE: bicycle …) when no file declares it, else SUMO's default for a
        vehicle (passenger) or, with ``default``, for a person (pedestrian)."""
        if self.conn is not None:
            try:
                vc = self.conn.vehicletype.getVehicleClass(vt)
                if vc:
                    return str(vc)
            except Exception:
                pass
        if info is None and vt in SUMO_DEFAULT_VTYPES:
            return SUMO_DEFAULT_VTYPES[vt]
        return (info.vclass if info is not None and info.vclass else None) or default

    def _made_for(self, vclass: str) -> list[str]:
        """The equations made for a vClass (plain names: any)."""
        return [n for n in self.names if (self.vclasses[n] is None or vclass in self.vclasses[n])
                and n not in self.energy_of]

    def _default_emission_class(self, vt: str, vclass: str, written: bool = False) -> tuple[str, str]:
        """SUMO's default emissionClass for the vType (SUMO's own when it writes none and the
        run has a connection, else SUMO's default for the vClass), and where it came from."""
        if self.conn is not None and not written:
            try:
                ec = self.conn.vehicletype.getEmissionClass(vt)
                if ec:
                    return str(ec), "SUMO's default (none written)"
            except Exception:
                pass
        return (SUMO_DEFAULT_EMISSION_CLASS.get(vclass, SUMO_DEFAULT_EMISSION_CLASS_OTHER),
                f"SUMO's default for vClass {vclass} ("
                + ("the written one names no fuel" if written else "none written") + ")")

    def _by_carrier(self, vt: str, info, vclass: str, app: np.ndarray) -> np.ndarray:
        """``app`` without the chain equations of another energy carrier than the vType's:
        its written emissionClass's; where that names none (or none is written) and chains
        of several carriers apply, SUMO's default one's when the scenario says
        ``default_carrier`` — which then also chooses between a hybrid's and a conventional
        engine's chains of one carrier (a bus that writes none: the diesel bus's)."""
        present = {self.carrier_of[n] for n, a in zip(self.names, app) if a} - {None}
        if not present:
            return app
        ec = info.emission_class if info is not None else None
        carrier, src = energy_carrier(ec), "written"
        if info is None and vt not in SUMO_DEFAULT_VTYPES and self.conn is not None:
            # a vType the files do not declare, made at run time (vehicletype.copy and its
            # setters): its carrier is the class SUMO gives it (before, every chain booked it)
            try:
                ec = str(self.conn.vehicletype.getEmissionClass(vt)) or None
            except Exception:  # (a connection that cannot say)
                ec = None
            carrier, src = energy_carrier(ec), "SUMO's (a vType made at run time)"
        if ec is None and info is not None:  # none written: SUMO's battery device runs it on its
            # Energy model (param has.battery.device; device.battery.probability 1) — electric
            # even where one carrier's chains alone apply (a moped's, a bus's petrol/diesel)
            run_ec = run_emission_class(info, battery_switch(self.sc))
            if run_ec is not None:
                ec, carrier, src = run_ec, energy_carrier(run_ec), "SUMO's battery device (none written)"
        if carrier is None:  # none written, or a name of no known carrier
            if not getattr(self.sc, "default_carrier", False):
                return app
            ec, src = self._default_emission_class(vt, vclass, written=ec is not None)
            if len(present) < 2:  # one carrier's chains book it; a hybrid's only if SUMO's class is one
                return self._by_powertrain(vt, ec, src, app)
            carrier = energy_carrier(ec)
            if carrier is None:
                return app
        wrong = [i for i, n in enumerate(self.names) if app[i] and self.carrier_of[n] not in (None, carrier)]
        if wrong:
            app = app.copy()
            app[wrong] = 0.0
            self.carriers[vt] = {"emission_class": ec, "from": src, "carrier": carrier,
                                 "not_booked_by": [self.names[i] for i in wrong]}
        return self._by_powertrain(vt, ec, src, app)

    def _by_powertrain(self, vt: str, ec: str, src: str, app: np.ndarray) -> np.ndarray:
        """``app`` with the fuel chains of one powertrain where several apply: the class's own
        (:func:`powertrain_of_class`: a plug-in hybrid's, a full hybrid's or a conventional
        engine's), else the nearest in :data:`POWERTRAIN_ORDER`; where only one kind applies,
        it books (a hybrid that only conventional engines' chains book is noted:
        ``no_hybrid_chain`` names them, sim/powertrain.no_hybrid_chain_warning)."""
        fuel = [i for i, n in enumerate(self.names) if app[i] and n in self.hybrid_of]
        kind = {i: "plug-in hybrid" if self.names[i] in self.plug_in else
                ("hybrid" if self.hybrid_of[self.names[i]] else "conventional") for i in fuel}
        want = powertrain_of_class(ec)
        if set(kind.values()) == {"conventional"} and want != "conventional":  # only conventional chains
            self.powertrains[vt] = {"emission_class": ec, "from": src, "powertrain": "conventional",
                                    "no_hybrid_chain": [self.names[i] for i in fuel], "not_booked_by": []}
        if len(set(kind.values())) < 2:
            return app
        got = next(k for k in POWERTRAIN_ORDER[want] if k in kind.values())
        other = [i for i in fuel if kind[i] != got]
        app = app.copy()
        app[other] = 0.0
        self.powertrains[vt] = {"emission_class": ec, "from": src, "powertrain": got,
                                "not_booked_by": [self.names[i] for i in other]}
        if got == "plug-in hybrid":  # (model/chain_plugin.py: spent from each departure)
            self.powertrains[vt]["battery"] = "charged at each departure (unless declared: chain.departure_charge): its usable energy first, then fuel"
        return app

    def own_mass(self, ledger, i: int, vt: str, copy: str) -> bool:
        """Book vehicle row ``i`` of vType ``vt``, now on its own copy ``copy``, at the copy's
        mass: the scenario's ``[vtypes."<copy>"] mass_kg`` where it gives one (all an FCD
        replay can know: FCD names the copy, not its mass), else, live, SUMO's mass of the
        copy where a script set another than ``vt``'s (plus ``vt``'s loading, which SUMO adds
        and the copy keeps), else ``vt``'s booked mass (a copy
        made by another setter; a mass set back). A replay told none books ``vt``'s and
        lists the copy in :attr:`untold_copies`. True when the booked mass changed."""
        told = getattr(self.sc, "vtype_data", {}).get(copy, {}).get("mass_kg")
        base = self.cache[vt][0] if vt in self.cache else float(ledger.veh_mass[i])
        if told is not None:
            tiny_mass(copy, self.cache.get(vt, (None,) * 4)[3], m := float(told),
                      f"vtypes.{copy}.mass_kg in {getattr(self.sc, 'path', None) or 'the scenario'}")
            self.seen.add(copy)  # (its [vtypes] entry was used)
            if getattr(self.conn, "is_replay", False):
                self.told_copies[copy] = m
        elif getattr(self.conn, "is_replay", False):
            self.untold_copies.setdefault(copy, vt)
            return False
        else:
            tget = self.conn.vehicletype
            m = float(tget.getMass(copy))
            if not (m > 0 and np.isfinite(m)) or m == float(tget.getMass(vt)):
                m = base
            else:  # SUMO adds the type's loading, which the copy keeps (EnergyParams::getTotalMass)
                info = self.files.get(vt)
                m += info.loading_kg if info is not None else 0.0
        if m == float(ledger.veh_mass[i]):
            return False
        ledger.veh_mass[i] = m
        return True

    def type_masses_changed(self) -> dict[str, float]:
        """vType → its new booked mass [kg]: the watched vTypes (:attr:`watched`) whose mass a
        script set (``vehicletype.setMass``) since they were resolved, at SUMO's new mass plus
        their loading, as SUMO books their vehicles from then on (its later departures too)."""
        out = {}
        for vt, (was, loading) in list(self.watched.items()):
            m = self._sumo_mass(vt)
            if m is not None and m != was:
                self.watched[vt] = (m, loading)
                out[vt] = m + loading
                self.cache[vt] = (out[vt], *self.cache[vt][1:])
        return out

    def own_copy(self, ledger, i: int, vt: str, copy: str) -> bool:
        """Vehicle row ``i`` of vType ``vt`` now runs on its own copy ``copy`` (``<vt>@<id>``:
        SUMO makes one when a script calls the vehicle's setMass, setEmissionClass, …): its
        mass when the script set another (:meth:`own_mass`), and, live, where the copy's
        emissionClass names another energy carrier than ``vt``'s, the equations of that
        carrier among those made for its class (a petrol car a script turns electric: the
        battery chain, not the petrol one). True when either changed."""
        changed = self.own_mass(ledger, i, vt, copy)
        if getattr(self.conn, "is_replay", False):  # (FCD names the copy, not its emissionClass)
            return changed
        tget = self.conn.vehicletype
        made = self.made_for_app.get(vt)
        ec = str(tget.getEmissionClass(copy)) or None
        carrier = energy_carrier(ec)
        if made is None or carrier is None or ec == (str(tget.getEmissionClass(vt)) or None):
            return changed
        app = made.copy()
        app[[k for k, n in enumerate(self.names) if app[k] and self.carrier_of[n] not in (None, carrier)]] = 0.0
        app = self._by_powertrain(copy, ec, "set by a script on the vehicle", app)
        if app.any() and not np.array_equal(app, ledger.veh_app[i]):
            ledger.set_app(i, app)
            self.carriers[copy] = {"emission_class": ec, "from": "set by a script on the vehicle",
                                   "carrier": carrier, "not_booked_by": [n for n, a, b in zip(self.names, app, made)
                                                                         if b and not a]}
            changed = True
        return changed

    def __call__(self, vt: str, vid: str):
        out = self.cache.get(vt)
        if out is None:
            out = self.cache[vt] = self._resolve(vt, vid)
        if not out[2]:
            if out[4] == "filter":
                self.excluded += 1
            elif out[4] == "carrier":
                for key, k in (("by_carrier", out[3]), ("by_vtype", vt)):
                    d = self.skipped.setdefault(key, {})
                    d[k] = d.get(k, 0) + 1
            else:
                for key, k in (("by_vclass", out[3]), ("by_vtype", vt)):
                    self.skipped[key][k] = self.skipped[key].get(k, 0) + 1
        return out[:4]

    def skip_person(self, vt: str) -> None:
        """Count a departing person (vType ``vt``) as skipped: persons are not booked, and
        a person is a pedestrian whatever its vType's vClass says (a type nobody declared,
        e.g. SUMO's DEFAULT_PEDTYPE in an FCD replay, or one redeclared without a vClass,
        which SUMO reads as passenger)."""
        for key, k in (("by_vclass", "pedestrian"), ("by_vtype", vt)):
            self.skipped[key][k] = self.skipped[key].get(k, 0) + 1

    def _resolve(self, vt: str, vid: str):
        from sumo_drvpw.sim.vtypes import (DEFAULT_MASS_KG, DEFAULT_MASS_SOURCE, GENERIC_VCLASSES,
                                           vehicle_body)

        sc = self.sc
        data = sc.vtype_data.get(vt, {})
        info = self.files.get(vt)
        vclass = self._vclass(vt, info)
        sc_classes = getattr(sc, "vclass_data", {})
        cdata = sc_classes.get(vclass, {})
        if sc.vtype_filter is not None and vt not in sc.vtype_filter:
            return (np.nan, np.zeros(len(self.names)), False, vclass, "filter")
        eq = data.get("equations")
        if eq is None:
            one = (info.equation if info is not None else None) or self._param(vt, "drvpw.equation")
            eq = [one] if one else cdata.get("equations")
        explicit = eq is not None
        chosen = eq  # the equations named (None: those made for the class)
        if eq is None:
            eq = self._made_for(vclass)
        app = np.array([1.0 if n in eq else 0.0 for n in self.names])
        # a vClass may say what the vehicle may use, not what it is (generic classes; a car in
        # vClass bus for the bus lanes): then its emission class, shape or id names the
        # vehicle (its equations, class settings, default mass)
        named = vehicle_body(vclass, info, vt)
        body = named[0] if named is not None else vclass
        if named is not None and not explicit and (vclass not in GENERIC_VCLASSES or not app.any()):
            chosen = sc_classes.get(body, {}).get("equations")
            eq = chosen or self._made_for(body)
            app = np.array([1.0 if n in eq else 0.0 for n in self.names])
            if app.any():
                self.booked_as[vt] = {"vclass": vclass, "booked_as": body, "from": named[1]}
        app = own_energy(self.names, self.energy_of, vt, chosen, app)
        if not app.any():
            return (np.nan, app, False, vclass, "vclass")
        if not explicit:
            self.made_for_app[vt] = app.copy()
            app = self._by_carrier(vt, info, body, app)
            if not app.any():
                return (np.nan, app, False, vclass, "carrier")
        if vt not in self.booked_as and vclass not in GENERIC_VCLASSES:
            body = vclass   # its own equations, so its own class's mass
        if body != vclass and cdata.get("mass_kg") is None:
            cdata = sc_classes.get(body, {})
        mass, said = data.get("mass_kg"), "the scenario's mass_kg"
        if mass is None and info is not None:
            mass, said = info.mass_kg, written_mass(info)
        if mass is None:
            p = self._param(vt, "drvpw.mass")
            if p:
                try:
                    mass, said = float(p), "its drvpw.mass"
                except ValueError:
                    raise UserError(f"vType '{vt}': drvpw.mass is not a number: {p!r}") from None
        tiny_mass(vt, vclass, mass, said)
        if mass is None and info is None and vt not in SUMO_DEFAULT_VTYPES:
            mass = self._sumo_mass(vt)  # a vType made during the run (TraCI copy, setMass)
            if mass is not None:  # or loaded from a file the plug-in did not read: said
                self.sumo_masses[vt] = {"vclass": vclass, "mass_kg": mass}
        fixed = [self.energy_mass.get(n) for n, a in zip(self.names, app) if a]
        if mass is None and all(fixed):  # booked by its vtype_energy only: SUMO's mass, no class default
            mass = fixed[0]
        # a class mass for a vType that gives none: plus the vType's SUMO loading (payload)
        loading = info.loading_kg if info is not None else 0.0
        if mass is None and cdata.get("mass_kg") is not None:
            mass = cdata["mass_kg"] + loading
        if mass is None and getattr(sc, "default_masses", True) and body in DEFAULT_MASS_KG:
            mass = DEFAULT_MASS_KG[body] + loading
            self.assumptions[vt] = {"vclass": body, "mass_kg": mass,
                                    "source": DEFAULT_MASS_SOURCE[body]
                                    + (f" + loading {loading:g} kg" if loading else "")}
            # no heavier than the gross weight its written emissionClass names (a ≤ 7.5-t truck)
            limit = class_mass_limit_kg(info.emission_class if info is not None else None)
            if limit is not None and not VAN_MAX_MASS_KG < limit <= MASS_MAX_KG:  # (SUMO refuses it)
                raise UserError(f"vType '{vt}' (defined in {info.source}): emissionClass "
                                f"'{info.emission_class}' names a gross weight of {limit:g} kg: no HBEFA "
                                f"class bounds its vehicles under {VAN_MAX_MASS_KG:g} or over "
                                f"{MASS_MAX_KG:g} kg (a typo? SUMO knows no such class)")
            if limit is not None and mass > limit:
                self.assumptions[vt].update(mass_kg=limit, capped_from_kg=mass, emission_class=info.emission_class)
                self.assumptions[vt]["source"] += f", capped at its emissionClass's gross weight {limit:g} kg"
                mass = limit
            length = info.length_m if info is not None else None
            if body in CAR_VCLASSES and length is not None and length < SHORT_CAR_M:
                self.assumptions[vt]["length_m"] = length  # a microcar or pod: warned of
        if mass is None:
            where = f" (defined in {info.source})" if info is not None else \
                " (not defined in the route/additional files: SUMO's default type?)"
            raise UserError(
                f"vType '{vt}' of vehicle '{vid}'{where} has no mass: give it a mass attribute, "
                f'a <param key="drvpw.mass" value="..."/>, or vtypes.{vt}.mass_kg or '
                f"vclasses.{vclass}.mass_kg in the scenario (or leave it out with vehicles.vtypes)")
        for i, n in enumerate(self.names):  # its own vtype_energy beside other battery chains
            if app[i] and self.energy_of.get(n) == vt:
                others = [o for o, a in zip(self.names, app)
                          if a and o != n and self.carrier_of.get(o) == "electricity"]
                if others:
                    self.also_booked[n] = others
        far = {n: m for n, a in zip(self.names, app) if a and (m := self.calibrated_at.get(n))
               and max(m / mass, mass / m) >= MASS_FAR}
        if far:
            self.mass_far[vt] = {"mass_kg": float(mass), "calibrated_at_kg": far}
        if data.get("mass_kg") is None and not (info is not None and info.drvpw_mass) \
                and not self._param(vt, "drvpw.mass") and (sm := self._sumo_mass(vt)) is not None:
            self.watched[vt] = (sm, loading)
        at_fixed = {n: self.fixed_far_eq[n] for n, a in zip(self.names, app) if a and n in self.fixed_far_eq}
        if at_fixed:
            self.fixed_far[vt] = at_fixed
        return (float(mass), app, True, vclass, "")


def builtin_equations_for(vclass: str) -> list[str]:
    """The built-in equations of a bare SUMO config (:data:`~sumo_drvpw.sim.scenario.CONFIG_EQUATIONS`)
    made for ``vclass`` (what to add when a run's own equations leave it unbooked)."""
    from sumo_drvpw.model.equations import load_equation
    from sumo_drvpw.sim.scenario import CONFIG_EQUATIONS

    return [n for n in CONFIG_EQUATIONS if vclass in (load_equation(n).vclasses or ())]


def few(items: list[str], most: int = 3) -> str:
    """The first ``most`` of ``items`` joined, and how many more: a warning's list kept short."""
    return ", ".join(items[:most]) + (f" and {len(items) - most} more" if len(items) > most else "")


def carrier_warning(carriers: dict[str, dict], skipped: dict[str, int], idle: list[str]) -> str:
    """One line, for a run where a chain equation booked no vehicle (``idle``) or vehicles
    were left with no equation (``skipped``: vClass → count) because their emissionClass
    names another energy carrier: the vTypes each chain left out, grouped by carrier →
    equations, up to three vType ids each."""
    groups: dict[tuple[str, tuple], list[str]] = {}
    for vt, c in sorted(carriers.items()):
        eqs = tuple(e for e in c["not_booked_by"] if e in idle) if not skipped else tuple(c["not_booked_by"])
        if eqs:
            groups.setdefault((c["carrier"], eqs), []).append(f"{vt} ({c['emission_class']})")
    parts = [f"{', '.join(eqs)} not for {carrier}: " + few(v) for (carrier, eqs), v in sorted(groups.items())]
    left = (" — vehicles with no equation left were not booked: " + ", ".join(
        f"{c} {n}" for c, n in sorted(skipped.items()))) if skipped else ""
    return ("chain equations book only vehicles whose emissionClass names their fuel or the battery: "
            + "; ".join(parts) + left
            + " (summary.json assumptions.energy_carrier; vtypes.<id>.equations chooses instead)")


def booked_as_warning(booked_as: dict[str, dict]) -> str:
    """One line: the vTypes booked as the vehicle their emissionClass, guiShape, id or
    length names rather than by their vClass (sim/vtypes.vehicle_body), grouped by vClass →
    vehicle (up to three vType ids each)."""
    groups: dict[tuple[str, str], list[str]] = {}
    for vt, b in sorted(booked_as.items()):
        groups.setdefault((b["vclass"], b["booked_as"]), []).append(f"{vt} ({b['from']})")
    parts = [f"{c} → {body}: " + few(v)
             for (c, body), v in sorted(groups.items())]
    return ("vTypes whose vClass does not say what vehicle they are were booked as the one "
            "their emissionClass, guiShape, id or length names: " + "; ".join(parts)
            + " (summary.json assumptions.booked_as; vclasses.<vClass>.equations chooses instead)")


def calibration_mass_warning(mass_far: dict[str, dict]) -> str | None:
    """One line, or None: the vTypes booked by an equation calibrated on a vehicle of quite
    another mass (:attr:`VTypeResolver.mass_far`), grouped by equation (up to three each)."""
    groups: dict[tuple[str, float], list[str]] = {}
    for vt, f in sorted(mass_far.items()):
        for eq, m in f["calibrated_at_kg"].items():
            groups.setdefault((eq, m), []).append(f"{vt} ({f['mass_kg']:,.0f} kg)")
    if not groups:
        return None
    parts = [f"{eq} (calibrated at {m:,.0f} kg): " + few(v)
             for (eq, m), v in sorted(groups.items())]
    return (f"equations book vTypes {MASS_FAR:g} times as heavy or as light as the vehicle they were "
            "calibrated on, or more: " + "; ".join(parts) + " — their acc, grade and roll terms scale with the vType's "
            "mass, but the aero term (the calibration vehicle's drag) and whatever else the fit absorbed do "
            "not: calibrate an equation on such vehicles, or name one for them (summary.json "
            "assumptions.calibration_mass; vclasses.<vClass>.equations)")


def fixed_mass_listing(fixed_far: dict[str, dict]) -> dict[str, dict]:
    """summary.json ``assumptions.calibration_mass_fixed``: per equation that books at a fixed
    mass far from its calibration mass (:attr:`VTypeResolver.fixed_far`), that mass, the
    calibration mass and the vTypes it booked [kg]."""
    out: dict[str, dict] = {}
    for vt, eqs in sorted(fixed_far.items()):
        for eq, f in eqs.items():
            out.setdefault(eq, {**f, "vtypes": []})["vtypes"].append(vt)
    return dict(sorted(out.items()))


def fixed_mass_warning(fixed_far: dict[str, dict]) -> str | None:
    """One line, or None: the equations that book every vType at a fixed ``mass_kg``
    :data:`MASS_FAR` times as heavy or as light as the vehicle they were calibrated on, or
    more (their vTypes, up to three each)."""
    listing = fixed_mass_listing(fixed_far)
    if not listing:
        return None
    parts = [f"{eq} (at {f['mass_kg']:,.0f} kg, calibrated at {f['calibrated_at_kg']:,.0f} kg): "
             + few(f["vtypes"])
             for eq, f in listing.items()]
    return (f"equations book every vType at a fixed mass_kg {MASS_FAR:g} times as heavy or as light as the "
            "vehicle they were calibrated on, or more: " + "; ".join(parts) + " — their acc, grade and roll "
            "terms are booked at that mass, but the aero term (the calibration vehicle's drag) and whatever "
            "else the fit absorbed are the calibration vehicle's: give such an equation its calibration mass "
            "(or none: each vType's), or calibrate one on vehicles of that mass (summary.json "
            "assumptions.calibration_mass_fixed)")


def untold_copies_warning(untold: dict[str, str], told: dict | None = None) -> str:
    """One line: the vehicles' own vType copies an FCD replay saw (``<type>@<id>``) and booked
    at their type's mass (``untold``) or at the one mass the scenario told (``told``), as no
    SUMO output carries a vehicle's mass (:attr:`VTypeResolver.untold_copies`, ``told_copies``)."""
    said = []
    if untold:
        said.append("booked at their type's mass: " + few(sorted(untold), 5) + " — where a script set a mass, "
                    "give it as [vtypes.\"<type>@<id>\"] mass_kg in the scenario")
    if told:
        said.append("booked from their first row at the one mass the scenario tells: " + few(sorted(told), 5))
    return ("the FCD names vehicles' own vType copies (<type>@<id>: SUMO makes one when a script calls "
            "setMass or another vType setter on the vehicle) but not their mass (nor do SUMO's emission, battery "
            "and vehroute outputs), so they were " + "; ".join(said) + " (one mass per copy: a mass a script set again during the "
            "trip, a second setMass on the vehicle, is not followed; summary.json assumptions."
            + "untold_copy_masses, told_copy_masses)")
