"""Scenario files (TOML): which SUMO run, which equations, which vehicles, wind, air, classes.

The schema, with every key's meaning, unit and default, is docs/scenario.md ("Schema");
``_SCHEMA`` below lists the keys. Every table is optional except ``[sumo]`` and
``equations``; paths are relative to the scenario file. Every value is checked for its
type (booleans true/false, numbers finite, lists TOML arrays, tables TOML tables, vClass
names SUMO's): bad input is a UserError naming the file and the key.

Vehicle mass (see :mod:`sumo_drvpw.sim.vtypes`): scenario ``mass_kg`` > vType param
``drvpw.mass`` > vType ``mass`` attribute written in the route/additional files. A vType
with none of them has no mass: SUMO would silently use its default, so this is an error.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path

from sumo_drvpw.model.air import air_density
from sumo_drvpw.model.constants import KELVIN, MASS_MAX_KG, P_STD_KPA, RHO_DEFAULT
from sumo_drvpw.model.equations import NAME_PATTERN, Equation, check_equation, check_vclass, load_equation
from sumo_drvpw.sim.scenario_paths import config_files, sumo_file_list
from sumo_drvpw.sim.scenario_values import (AIR_RANGES, WIND_MAX_MPS, _bool, _check_table, outputs_onto_inputs,
                                            _choice, _in_range, _num, _path, _share, _strlist, _strmap,
                                            sumo_seconds, sumo_time)  # noqa: F401 (sumo_seconds: public here too)
from sumo_drvpw.sim.sumo_start import NO_RUN_OPTIONS, check_option_values
from sumo_drvpw.sim.vtype_energy import VTYPE_ENERGY, named_in_table, placeholder, reserved_name
from sumo_drvpw.errors import UserError
from sumo_drvpw.sim.sumo_outputs import (additional_outputs, device_wanted, is_output_option,
                                         option_input_files)
from sumo_drvpw.fileio import read_toml
from sumo_drvpw.model.terms import measurement_finding, parse_term

DEFAULT_HIGHWAY_TYPES = ("highway.motorway", "highway.motorway_link", "highway.trunk",
                         "highway.trunk_link")
#: Speed limit at or above which an edge is highway by default [km/h].
DEFAULT_HIGHWAY_MIN_SPEED_KMH = 80.0

_SCHEMA: dict[str, set[str] | None] = {
    "equations": None,
    "sumo": {"config", "net", "routes", "additional", "begin", "end", "step_length",
             "connection", "gui", "options", "acceleration", "positions"},
    "vehicles": {"vtypes", "default_masses", "transportable_mass", "default_carrier", "cold_start"},
    "vtypes": None,  # table of vType id → {mass_kg, equations, cold_start}
    "vclasses": None,  # table of SUMO vClass → {mass_kg, equations, cold_start}
    "wind": {"speed_mps", "from_deg", "heading"},
    "air": {"density_kgm3", "temperature_c", "pressure_kpa"},
    "road_class": {"highway_min_speed_kmh", "highway_types", "types", "edges"},
    "slope": {"window_m", "max_rad", "tolerance_rad", "reference"},
    "outputs": {"trace", "edgedata", "figures", "difference", "progress", "period",
                "sumo_device"},
}
_VTYPE_KEYS = {"mass_kg", "equations", "cold_start", "battery_charge_wh"}  # (the last: [vtypes] only)
MAX_RAD_LIMIT = 1.5  #: the steepest [slope] max_rad [rad] (tan θ of the profile: 90° is a wall)
#: keyword overrides accepted by run_scenario (and the CLI)
OVERRIDES = {"begin", "end", "step_length", "connection", "gui", "options", "equations",
             "trace", "edgedata", "figures", "progress", "difference", "acceleration",
             "slope_reference", "wind_heading", "positions", "period", "sumo_device",
             "air_temperature_c", "cold_start"}


#: the equations of a bare SUMO config (``run X.sumocfg``): every motor vehicle class has one — cars by
#: VSP (LDV 1999), the seed paper's DrvPw and MOVES's passenger car; trucks, buses and motorcycles by their
#: MOVES type — and cars and vans by the EPA fleet's fuel chains, trucks and buses by their MOVES type's
#: diesel chain (docs/hdv-fuel.md) — a hybrid bus by the diesel-electric hybrid's (docs/hdv-hybrid.md) —,
#: motorcycles and mopeds by their petrol chains (docs/mc-fuel.md),
#: electric cars by the i3's battery chain, each vehicle by the carrier of its emissionClass (SUMO's
#: default where it writes none: ``default_carrier``; an evehicle's is electric), a hybrid's class
#: (a plug-in's petrol share) by the full hybrids' chain (sim/resolver.py)
CONFIG_EQUATIONS = ("vsp_ldv1999", "drvpw_prius3", "moves_passenger_car", "moves_motorcycle",
                    "moves_light_commercial_truck", "moves_single_unit_truck", "moves_combination_truck",
                    "moves_transit_bus", "moves_intercity_bus", "epa_gasoline_car", "epa_diesel_car",
                    "epa_gasoline_light_truck", "epa_diesel_light_truck", "moves_single_unit_truck_diesel",
                    "moves_combination_truck_diesel", "moves_transit_bus_diesel", "moves_intercity_bus_diesel",
                    "moves_transit_bus_hybrid_diesel", "bmw_i3_battery", "epa_gasoline_hybrid_car", "epa_gasoline_phev_car",
                    "moves_motorcycle_petrol", "moves_moped_petrol")

#: the class of an edge that only vehicles of one of these vClass groups may use (the vClasses
#: its lanes allow, persons and containers on foot aside): no road, so neither city nor
#: highway by its speed (a tram line at 90 km/h was a highway); SUMO's deprecated names too
NON_ROAD_CLASSES = {
    "rail": frozenset({"rail", "rail_urban", "rail_electric", "rail_fast", "tram", "subway", "cable_car",
                       "lightrail", "cityrail", "rail_slow"}),
    "waterway": frozenset({"ship"}),
    "air": frozenset({"aircraft", "drone"}),
}
#: the heaviest vType mass [kg] of each class's vClasses (sim/vtypes.py refuses more: a typo): the
#: heaviest trains run some 100,000 t, the largest ships some 650,000 t displaced, aircraft 640 t
NON_ROAD_MASS_MAX_KG = {"rail": 2.0e8, "waterway": 1.0e9, "air": 1.0e6}
#: the heaviest vType mass [kg] of a person's vClasses (sim/vtypes.py refuses more: a rider adds it to
#: its vehicle, as SUMO does; a pedestrian vType of mass="7500" for 75.00 booked a car 7.5 t heavier)
ON_FOOT_MASS_MAX_KG = {"pedestrian": 500.0, "wheelchair": 500.0}
#: vClasses that move on foot: a footway beside a tram line does not make it a road
ON_FOOT_VCLASSES = frozenset({"pedestrian", "wheelchair", "container"})


def non_road_class(allowed) -> str | None:
    """The :data:`NON_ROAD_CLASSES` class of an edge whose lanes allow the vClasses ``allowed``
    (their union), or None: a road (any road vehicle allowed), or no vehicle at all."""
    vehicles = set(allowed or ()) - ON_FOOT_VCLASSES
    return next((c for c, group in NON_ROAD_CLASSES.items() if vehicles and vehicles <= group), None)


@dataclass
class RoadClassRule:
    """How an edge gets its road class: edge id map > type map > no road (rail, waterway, air:
    :func:`non_road_class`) > highway types/speed > city."""

    highway_min_speed_mps: float = DEFAULT_HIGHWAY_MIN_SPEED_KMH / 3.6
    highway_types: tuple[str, ...] = DEFAULT_HIGHWAY_TYPES
    types: dict[str, str] = field(default_factory=dict)
    edges: dict[str, str] = field(default_factory=dict)

    def classify(self, edge_id: str, edge_type: str, speed_mps: float, allowed=None) -> str:
        """Road class of a (non-internal) edge; speed limit in [m/s]; ``allowed``: the vClasses
        its lanes allow (None: any)."""
        if edge_id in self.edges:
            return self.edges[edge_id]
        if edge_type in self.types:
            return self.types[edge_type]
        if (other := non_road_class(allowed)) is not None:
            return other
        if edge_type in self.highway_types or speed_mps >= self.highway_min_speed_mps - 1e-6:
            return "highway"
        return "city"

    @property
    def classes(self) -> list[str]:
        """Every class the rule can produce, city and highway first."""
        out = ["city", "highway"]
        for c in list(self.types.values()) + list(self.edges.values()):
            if c not in out:
                out.append(c)
        return out


@dataclass
class Scenario:
    """A parsed scenario: SUMO command pieces, equations and the physics settings (SI)."""

    path: Path | None
    sumo_args: list[str]
    route_files: list[Path]
    net_file: Path
    begin: float | None
    end: float | None
    step_length: float | None
    connection: str
    gui: bool
    equations: list[Equation]
    vtype_filter: list[str] | None
    vtype_data: dict[str, dict]
    wind_speed: float
    wind_from_deg: float
    rho: float
    road_class: RoadClassRule
    #: air temperature [°C] when the scenario gives air.temperature_c (the equations'
    #: ``cold`` factor and the chains' HVAC read it as ``ambient_c``); None: not given
    air_temperature_c: float | None = None
    slope_window: float = 20.0
    slope_max: float = 0.25
    slope_tol: float = 0.01
    slope_reference: str = "geometry"
    acceleration: str = "speed_difference"
    wind_heading: str = "geometry"
    positions: str = "tracked"
    trace: bool = False
    edgedata: bool = True
    figures: bool = True
    difference: list[str] | None = None
    progress: bool = True
    #: SUMO vClass → {"mass_kg": default mass [kg], "equations": [names]}
    vclass_data: dict[str, dict] = field(default_factory=dict)
    #: vTypes without a mass take their vClass's built-in default mass (else: error)
    default_masses: bool = True
    #: where a vType writes no emissionClass and chain equations of different energy carriers
    #: are made for its vClass, book it by the one of SUMO's default emissionClass for the
    #: vClass (petrol car, diesel van, truck and bus); else every such chain books it, as
    #: alternatives. Default: on for the plug-in's own equations (a bare SUMO config), off
    #: for equations a user chose. A written emissionClass always decides.
    default_carrier: bool = False
    #: share of the trips departing during the run that start a cold engine, 0 … 1 (true:
    #: 1, false: 0): fuel chains book that share of their ``cold_start_fuel_l`` at each
    #: departure (0: trips start warm, e.g. through traffic); a vType's or vClass's own
    #: ``cold_start`` (``vtype_data``, ``vclass_data``) replaces it for its vehicles
    cold_start: float = 0.0
    #: riding persons add their vTypes' masses, as in SUMO (EnergyParams::getTotalMass)
    transportable_mass: bool = True
    #: edgeData interval [s] (None: one interval for the whole run)
    period: float | None = None
    #: where the period was given, for its messages (the file's key, or the run's)
    period_from: str = "outputs.period"
    #: also run SUMO's emissions device and put its per-vehicle totals beside ours
    sumo_device: bool = False
    #: the SUMO config or the SUMO options (sumo.options, a run's options) enable the
    #: emissions device (device.emissions.probability > 0 or .explicit): its per-vehicle
    #: totals go beside ours unless outputs.sumo_device = false, and the run leaves the
    #: device settings as they are
    sumo_device_in_config: bool = False
    #: output options the SUMO config sets (option → file as written there); a run
    #: redirects them into its output folder's ``sumo/`` (sim.sumo_outputs.sumo_output_args)
    config_outputs: dict[str, str] = field(default_factory=dict)
    #: outputs declared in additional files, written beside them unless a run redirects them (sim.sumo_outputs)
    additional_outputs: list[str] = field(default_factory=list)
    #: the additional files SUMO loads (absolute; a config's or ``sumo.additional``)
    additional_files: list[Path] = field(default_factory=list)
    end_given: bool = False  # ``end`` given to the run (an override), not the file's or config's


#: the scenario's SUMO times [s] SUMO takes: no negative begin; steps of at least SUMO's
#: millisecond; an end within SUMO's time range, with room
SUMO_TIME_RANGES = {"begin": (0.0, 1e9), "end": (0.0, 1e9), "step_length": (0.001, 3600.0)}


def _where(path) -> str:
    return str(path) if path else "<scenario>"


def device_in_config(cfgvals: dict[str, str]) -> bool:
    """Whether a SUMO config's options enable the emissions device for some vehicles."""
    try:
        if float(cfgvals.get("device.emissions.probability", "0") or 0) > 0:
            return True
    except ValueError:
        pass
    return bool(cfgvals.get("device.emissions.explicit", "").strip())


#: the options that enable SUMO's emissions device (:func:`device_in_config`)
DEVICE_OPTIONS = ("device.emissions.probability", "device.emissions.explicit")


def _given_options(args: list[str], keys) -> dict[str, str]:
    """The values SUMO's command-line ``args`` give the options ``keys`` (``--key v`` or
    ``--key=v``; the last one)."""
    out = {}
    for i, a in enumerate(args):
        k, eq, v = a[2:].partition("=")
        if a.startswith("--") and k in keys and (eq or i + 1 < len(args)):
            out[k] = v if eq else args[i + 1]
    return out


def cold_start_shares(data: dict[str, dict]) -> dict[str, float]:
    """vType (or vClass) → its own cold-start share, from ``Scenario.vtype_data`` (or
    ``vclass_data``): those that give one."""
    return {k: d["cold_start"] for k, d in (data or {}).items() if "cold_start" in d}


def resolve_equation(spec, base: Path | None, where: str) -> Equation:
    """Load one equation (Equation object, built-in name or TOML path relative to ``base``)
    and check it can run in SUMO (no log-only ``[column]`` or ``trip=`` factors);
    ``vtype_energy``: its stand-in (sim/vtype_energy.py)."""
    if spec == VTYPE_ENERGY:
        return placeholder()
    if isinstance(spec, Equation):
        eq = spec
        if not re.match(NAME_PATTERN, eq.name):
            raise UserError(f"{where}: equation name {eq.name!r} is not allowed: use a letter, "
                            "then letters, digits, '_', '.', '-' (at most 64 characters)")
        check_equation(eq, where)  # (a file's values are checked as it is read)
    else:
        p = Path(spec)
        try:
            eq = load_equation(base / p if base and not p.is_absolute() and (base / p).exists() else spec)
        except UserError as e:
            if str(e).startswith("unknown equation"):  # say where the name was written
                raise UserError(f"{where}: {e}") from None
            if str(e).startswith("equation file not found") and not p.is_absolute():
                here = Path(os.path.abspath(p))
                raise UserError(f"{where}: {e} (looked for {Path(os.path.abspath(base / p)) if base else here}"
                                + (f" and {here}" if base and Path(os.path.abspath(base / p)) != here else "") + ")") from None
            raise
        reserved_name(eq, where)  # vtype_energy, vtype_energy.…: the run's own
        if eq.chain is not None:  # (an Equation object's: check_equation)
            eq.chain.require_complete()
    src = eq.path or where  # the equation file the term is written in, else the scenario
    for t in eq.term_names:
        term = parse_term(t)
        why = (measurement_finding(t, term.signals[0]) or f"term '{t}' needs the log-only signal '{term.signals[0]}'"
               if term.signals else f"term '{t}' needs trip ids of a drive log" if any(f.startswith("trip=") for f in term.factors) else None)
        if why:
            raise UserError(f"{src}: equation '{eq.name}' cannot run in SUMO: {why}")
    return eq


def load_scenario(path: str | Path | None = None, doc: dict | None = None,
                  **overrides) -> Scenario:
    """Parse and check a scenario file (or an already parsed ``doc``); UserError on bad input.

    Parameters
    ----------
    path : scenario TOML file
    doc : parsed document instead of a file (paths then relative to the working directory)
    overrides : values replacing the file's (keys in ``OVERRIDES``)
    """
    where = _where(path)
    base = None
    if doc is None:
        if path is None:
            raise UserError("no scenario given")
        p = Path(path)
        if p.suffix == ".sumocfg":  # a bare SUMO config: every vehicle by its class's equations
            if not p.is_file():
                raise UserError(f"{p}: no such SUMO config")
            doc = {"sumo": {"config": p.name}, "equations": list(CONFIG_EQUATIONS)}
        else:
            doc = read_toml(p, "scenario file")
        # a config relative to where it is named, as SUMO reads it (a link's folder, not its
        # target's: files beside a linked config are the ones SUMO loads); a scenario file's
        # paths relative to the file itself (a link to it reads its target's folder)
        base = Path(os.path.abspath(p)).parent if p.suffix == ".sumocfg" else p.resolve().parent
        path = p
    bad = set(overrides) - OVERRIDES
    if bad:
        raise UserError(f"unknown override(s) {sorted(bad)} (known: {sorted(OVERRIDES)})")
    for key, val in doc.items():
        if key not in _SCHEMA:
            raise UserError(f"{where}: unknown key '{key}' (known: {', '.join(_SCHEMA)})")
        if _SCHEMA[key] is not None:
            _check_table(val, _SCHEMA[key], where, key)
    for table in ("vtypes", "vclasses"):
        if not isinstance(doc.get(table, {}), dict):
            raise UserError(f"{where}: '{table}' must be tables [{table}.<name>], got "
                            f"{doc[table]!r}")
        for name, d in doc.get(table, {}).items():
            _check_table(d, _VTYPE_KEYS, where, f"{table}.{name}")
            if table == "vclasses":
                check_vclass(name, where, f"[vclasses.{name}]")
    rel = (lambda s: (base / s) if base is not None and not Path(s).is_absolute() else Path(s))

    sumo = dict(doc.get("sumo", {}))
    for k in ("begin", "end", "step_length", "connection", "gui", "options", "acceleration",
              "positions"):
        if k in overrides:
            sumo[k] = overrides[k]
    if "config" in sumo:
        if "net" in sumo or "routes" in sumo or "additional" in sumo:
            raise UserError(f"{where}: give either sumo.config or sumo.net + sumo.routes "
                            "(+ sumo.additional)")
        cfg = rel(_path(sumo["config"], where, "sumo.config"))
        if not cfg.is_file():
            raise UserError(f"{where}: SUMO config not found: {cfg}")
        net, files, cfgvals = config_files(cfg)
        args = ["-c", str(cfg)]
        adds = [(cfg.parent / f).resolve() for f in sumo_file_list(cfgvals.get("additional-files"))]
    elif "net" in sumo:
        net = rel(_path(sumo["net"], where, "sumo.net")).resolve()
        routes = [rel(_path(r, where, "sumo.routes")).resolve()
                  for r in _strlist(sumo.get("routes", []), where, "sumo.routes")]
        adds = [rel(_path(r, where, "sumo.additional")).resolve()
                for r in _strlist(sumo.get("additional", []), where, "sumo.additional")]
        files, cfgvals = routes + adds, {}
        args = ["-n", str(net)]
        if routes:
            args += ["-r", ",".join(map(str, routes))]
        if adds:
            args += ["-a", ",".join(map(str, adds))]
    else:
        raise UserError(f"{where}: [sumo] needs 'config' or 'net' (+ 'routes')")
    if not net.is_file():
        raise UserError(f"{where}: SUMO network not found: {net}")
    times = {}
    for k in ("begin", "end", "step_length"):
        if k in sumo:
            times[k] = sumo_time(sumo[k], where, f"sumo.{k}", positive=(k == "step_length"))
            lo, hi = SUMO_TIME_RANGES[k]  # what SUMO refuses, or cannot hold, in words of the key
            if not lo <= times[k] <= hi:
                what = f"the run's {k}" if k in overrides else f"{where}: 'sumo.{k}'"
                raise UserError(f"{what} must be in [{lo:g}, {hi:g}] s, got {sumo[k]!r}")
            args += [f"--{k.replace('_', '-')}", repr(times[k])]
        elif k.replace("_", "-") in cfgvals:
            times[k] = sumo_time(cfgvals[k.replace("_", "-")], f"SUMO config {cfg}",
                                 k.replace("_", "-"), positive=(k == "step_length"))
    if "begin" in times and "end" in times and times["end"] <= times["begin"]:
        src = lambda k: f"the run's {k}" if k in overrides else f"sumo.{k}" if k in sumo else f"the {k} of SUMO config {cfg}"  # noqa: E731
        raise UserError(f"{where}: {src('end')} ({times['end']:g} s) is not after {src('begin')} ({times['begin']:g} s); "
                        f"both are simulation times: to run N s from the begin, end at {times['begin']:g} + N")
    opts = sumo.get("options", [])  # numbers as SUMO reads them: ["--seed", 7] is "--seed 7"
    if isinstance(opts, list):
        opts = [str(o) if isinstance(o, (int, float)) and not isinstance(o, bool) else o for o in opts]
    args += _strlist(opts, where, "sumo.options", '["--time-to-teleport", "120"]')
    given = {"configuration-file": "sumo.config"} if "config" in sumo else {"net-file": "sumo.net", **(  # SUMO's options
        {"route-files": "sumo.routes"} if routes else {}), **(  # the plug-in sets (an option twice: SUMO stops)
        {"additional-files": "sumo.additional"} if adds else {})}
    given.update({k.replace("_", "-"): ("the run's " if k in overrides else "sumo.") + f"{k} ({times[k]:g} s)"
                  for k in times if k in sumo})
    check_option_values(opts, where, given)  # ["-r"]: SUMO would say only "The parameter 'true' is not allowed"
    for i, a in enumerate(args):  # options after which SUMO runs no simulation (or waits for a client)
        name, _, val = str(a).partition("=")
        val = val or (str(args[i + 1]) if i + 1 < len(args) else "")
        harmless = (name == "--remote-port" and val == "0") or (name == "--num-clients" and val == "1")  # the defaults
        if name.startswith("-") and name.lstrip("-") in NO_RUN_OPTIONS and not harmless:
            raise UserError(f"{where}: sumo.options: {name} {NO_RUN_OPTIONS[name.lstrip('-')]}: the plug-in books a "
                            "simulation SUMO runs itself; leave it out")
    args = [x for a in args for x in (a.split("=", 1) if str(a).startswith("--mesosim=") or (  # as "--mesosim v",
        str(a).startswith("--") and "=" in a and is_output_option(a[2:].partition("=")[0])) else [a])]  # an output's too
    files, adds = option_input_files(args, [f for f in files if f not in adds], adds)  # -r, -a override
    outputs_onto_inputs(args, [p for p in (path, sumo.get("config") and cfg, net, *files) if p], where)
    for f in files:  # those SUMO loads: a config's own that the options replace need not exist
        if not f.is_file():
            raise UserError(f"{where}: SUMO input file not found: {f}")
    meso = cfgvals.get("mesosim", "false").strip().lower() in ("true", "1", "yes", "on", "x")
    src = f"SUMO config {cfg}" if meso else where
    if "--mesosim" in args:
        i = args.index("--mesosim")
        meso = i + 1 >= len(args) or args[i + 1].lower() not in ("false", "0", "no", "off")
        src = where
    if meso:
        raise UserError(f"{src}: mesosim: the mesoscopic simulation moves vehicles queue by "
                        "queue, without lanes or accelerations, so no driving power follows "
                        "from it; run the scenario microscopically (mesosim false)")
    connection = _choice(sumo.get("connection", "libsumo"), ("libsumo", "traci"), where, "sumo.connection")

    # no equations key: the plug-in's own equations, as for a bare SUMO config (a file that
    # only gives a config SUMO options); an empty list is refused below
    eq_specs = overrides.get("equations", doc.get("equations", list(CONFIG_EQUATIONS)))
    given = "equations" in overrides  # (from Python: one name, path or Equation alone too; paths as names)
    if given and isinstance(eq_specs, (str, os.PathLike, Equation)):
        eq_specs = [eq_specs]
    if given and isinstance(eq_specs, (list, tuple)):
        eq_specs = [str(e) if isinstance(e, os.PathLike) else e for e in eq_specs]
    if not eq_specs:
        raise UserError(f"{'the equations given to the run' if given else where}: 'equations' must name at least one equation")
    eq_where = "the equations given to the run" if given else f"{where}: equations"
    equations = [resolve_equation(s, None if given else base, eq_where)  # (given to the run: from the working folder)
                 for s in _strlist(eq_specs, "the run" if given else where, "equations", '["vsp_ldv1999"]')]
    names = [e.name for e in equations]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise UserError(f"{where}: equation name(s) {sorted(dup)} appear twice")

    veh = doc.get("vehicles", {})
    vfilter = _strlist(veh["vtypes"], where, "vehicles.vtypes") if "vtypes" in veh else None
    if vfilter == []:
        raise UserError(f"{where}: 'vehicles.vtypes' is empty: it would book no vehicle; name the vTypes to "
                        "book, or leave the key out to book all")
    def entries(table: str) -> dict[str, dict]:
        out = {}
        for vt, d in doc.get(table, {}).items():  # keys were checked with the schema above
            entry = {}
            if "mass_kg" in d:
                entry["mass_kg"] = _num(d["mass_kg"], where, f"{table}.{vt}.mass_kg", positive=True, most=MASS_MAX_KG)
            if "equations" in d:
                eqs = _strlist(d["equations"], where, f"{table}.{vt}.equations")
                # a name, or a file of one of the scenario's equations (named by its name)
                eqs = [e if e in names or not e.endswith(".toml") else
                       resolve_equation(e, base, f"{where}: {table}.{vt}.equations").name for e in eqs]
                for e in eqs:
                    if e not in names and not named_in_table(e, table, str(vt), names, where):
                        raise UserError(f"{where}: {table}.{vt}.equations names '{e}', which is not "
                                        f"among the scenario's equations ({', '.join(names)}): list it there")
                entry["equations"] = eqs
            if "cold_start" in d:
                entry["cold_start"] = _share(d["cold_start"], where, f"{table}.{vt}.cold_start")
            if "battery_charge_wh" in d:  # a plug-in hybrid's charge at departure [Wh] (sim/chain_charge.py)
                key = f"{table}.{vt}.battery_charge_wh"
                if table == "vclasses" or _num(d["battery_charge_wh"], where, key) < 0:
                    raise UserError(f"{where}: '{key}' " + ("is a vType's: give it in [vtypes.<id>]" if table == "vclasses"
                                    else f"must be a number of Wh ≥ 0, got {d['battery_charge_wh']!r}"))
                entry["battery_charge_wh"] = float(d["battery_charge_wh"])
            out[str(vt)] = entry
        return out

    vdata = entries("vtypes")
    cdata = entries("vclasses")

    wind = doc.get("wind", {})
    ws = _num(wind.get("speed_mps", 0.0), where, "wind.speed_mps", most=WIND_MAX_MPS)
    wd = _num(wind.get("from_deg", 0.0), where, "wind.from_deg")
    if wind and "speed_mps" not in wind:
        raise UserError(f"{where}: [wind] needs speed_mps (and from_deg)")
    if ws < 0:
        raise UserError(f"{where}: wind.speed_mps must be ≥ 0, got {ws}")

    air = dict(doc.get("air", {}))
    if overrides.get("air_temperature_c") is not None:  # the density follows the temperature
        air.pop("density_kgm3", None)
        air["temperature_c"] = overrides["air_temperature_c"]
    t_air = None
    if "pressure_kpa" in air and "temperature_c" not in air:
        raise UserError(f"{where}: air.pressure_kpa goes with air.temperature_c (the density "
                        "follows from both)")
    if "density_kgm3" in air:
        if "temperature_c" in air:
            raise UserError(f"{where}: give air.density_kgm3 or air.temperature_c, not both")
        rho = _num(air["density_kgm3"], where, "air.density_kgm3", positive=True)
        _in_range(rho, AIR_RANGES["density_kgm3"], where, "air.density_kgm3")
    elif "temperature_c" in air:
        t = _num(air["temperature_c"], where, "air.temperature_c")
        pk = _num(air.get("pressure_kpa", P_STD_KPA), where, "air.pressure_kpa", positive=True)
        if t + KELVIN <= 0:
            raise UserError(f"{where}: air.temperature_c below absolute zero: {t}")
        _in_range(t, AIR_RANGES["temperature_c"], where, "air.temperature_c")
        _in_range(pk, AIR_RANGES["pressure_kpa"], where, "air.pressure_kpa")
        rho = air_density(t, pk)
        t_air = t
    else:
        rho = RHO_DEFAULT

    rc = doc.get("road_class", {})
    rule = RoadClassRule(
        highway_min_speed_mps=_num(rc.get("highway_min_speed_kmh", DEFAULT_HIGHWAY_MIN_SPEED_KMH),
                                   where, "road_class.highway_min_speed_kmh", True) / 3.6,
        highway_types=tuple(_strlist(rc.get("highway_types", list(DEFAULT_HIGHWAY_TYPES)),
                                     where, "road_class.highway_types", '["highway.motorway"]')),
        types=_strmap(rc.get("types", {}), where, "road_class.types", ("city", "highway", *NON_ROAD_CLASSES)),
        edges=_strmap(rc.get("edges", {}), where, "road_class.edges", ("city", "highway", *NON_ROAD_CLASSES)))
    sl = doc.get("slope", {})
    out = dict(doc.get("outputs", {}))
    for k in ("trace", "edgedata", "figures", "progress", "difference", "period", "sumo_device"):
        if k in overrides:
            out[k] = overrides[k]
    diff = out.get("difference")
    if diff is not None:
        diff = _strlist(diff, where, "outputs.difference", '["vsp_ldv1999", "drvpw_prius3"]')
    if diff is not None and "equations" in overrides and "difference" not in overrides \
            and any(d not in names for d in diff):
        diff = None  # the file's pair is gone with its equations: use the first two
    if diff is not None:
        if len(diff) != 2 or any(d not in names for d in diff) or diff[0] == diff[1]:
            raise UserError(f"{where}: outputs.difference must name two different equations of the "
                            f"scenario's ({', '.join(names)}), got {diff}")
    # the config's device options, replaced by the command line's (sumo.options, a run's
    # options; "--key value" or "--key=value", the last one) as SUMO takes them
    given_device = _given_options(args, DEVICE_OPTIONS)
    device_on = device_in_config({**cfgvals, **given_device})
    return Scenario(
        config_outputs={k: v for k, v in cfgvals.items() if is_output_option(k) and v.strip()},
        additional_outputs=additional_outputs(adds), additional_files=list(adds),
        path=Path(path) if path else None, sumo_args=args, route_files=files, net_file=net,
        begin=times.get("begin"), end=times.get("end"), step_length=times.get("step_length"), end_given="end" in overrides,
        connection=connection, gui=_bool(sumo.get("gui", False), where, "sumo.gui"),
        equations=equations,
        vtype_filter=vfilter, vtype_data=vdata, vclass_data=cdata,
        default_masses=_bool(veh.get("default_masses", True), where, "vehicles.default_masses"),
        default_carrier=_bool(veh.get("default_carrier", names == list(CONFIG_EQUATIONS)), where,
                              "vehicles.default_carrier"),
        cold_start=_share(overrides.get("cold_start", veh.get("cold_start", False)), where,
                          "vehicles.cold_start"),
        transportable_mass=_bool(veh.get("transportable_mass", True), where,
                                 "vehicles.transportable_mass"),
        wind_speed=ws, wind_from_deg=wd, rho=rho, air_temperature_c=t_air,
        road_class=rule,
        slope_window=_num(sl.get("window_m", 20.0), where, "slope.window_m", True),
        slope_max=_num(sl.get("max_rad", 0.25), where, "slope.max_rad", True, MAX_RAD_LIMIT),
        slope_tol=_num(sl.get("tolerance_rad", 0.01), where, "slope.tolerance_rad", True),
        slope_reference=_choice(overrides.get("slope_reference", sl.get("reference", "geometry")),
                                ("getslope", "geometry"), where, "slope.reference"),
        acceleration=_choice(sumo.get("acceleration", "speed_difference"),
                             ("getter", "speed_difference"), where, "sumo.acceleration"),
        positions=_choice(sumo.get("positions", "tracked"), ("tracked", "getter"), where,
                          "sumo.positions"),
        wind_heading=_choice(overrides.get("wind_heading", wind.get("heading", "geometry")),
                             ("getangle", "geometry"), where, "wind.heading"),
        trace=_bool(out.get("trace", False), where, "outputs.trace"),
        edgedata=_bool(out.get("edgedata", True), where, "outputs.edgedata"),
        figures=_bool(out.get("figures", True), where, "outputs.figures"), difference=diff,
        progress=_bool(out.get("progress", True), where, "outputs.progress"),
        sumo_device=device_wanted(_bool(out.get("sumo_device", device_on), where, "outputs.sumo_device"),
                                  device_on, given_device, where), sumo_device_in_config=device_on,
        period=None if out.get("period") is None else _num(out["period"], where,
                                                             "outputs.period", positive=True),
        period_from="the run's period" if "period" in overrides else f"{where}: outputs.period")
