"""Run a scenario: start SUMO, resolve vTypes, step the loop, write the outputs.

``run_scenario(scenario_path, out_dir, **overrides) -> summary`` runs a scenario file
(see :mod:`sumo_drvpw.sim.scenario`) with libsumo (or traci) and writes the outputs of
:mod:`sumo_drvpw.sim.outputs` into ``out_dir``. Modules: ``scenario`` (config), ``vtypes``
(mass and drvpw.* params from the route files), ``network`` (edge table, classes, robust
slopes), ``ledger`` (vectorized evaluation and accumulation), ``loop`` (the stepping loop,
connection passed in), ``sumo_start`` (starting SUMO), ``outputs``, ``sumo_outputs`` (SUMO's own outputs into ``OUT/sumo/``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sumo_drvpw.errors import UserError
from sumo_drvpw.sim.sumo_start import close_sumo, start_sumo
from sumo_drvpw.sim.vtype_energy import energy_vtype_of, own_energy
from sumo_drvpw.sim.vtypes import (SUMO_DEFAULT_EMISSION_CLASS, SUMO_DEFAULT_EMISSION_CLASS_OTHER,
                                   SUMO_DEFAULT_VTYPES, energy_carrier, equation_carrier,
                                   read_vtypes)
from sumo_drvpw.sim.sumo_outputs import (COPIES_PREFIX, SUMO_OUTPUT_DIR, is_output_option, naming_leaves_folder,
                                         output_naming, prepare_output_folder,
                                         redirect_additional_outputs, sumo_output_args, without_additional_files,
                                         written_file)

__all__ = ["run_scenario", "start_sumo", "close_sumo", "VTypeResolver"]


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
    that carrier or none (:func:`sumo_drvpw.sim.vtypes.energy_carrier`): a petrol chain
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
        self.names = [e if isinstance(e, str) else e.name for e in equations]
        #: equation name → vClasses it is made for (names given as plain strings: any)
        self.vclasses = {(e if isinstance(e, str) else e.name):
                         (None if isinstance(e, str) else set(e.vclasses)) for e in equations}
        #: equation name → energy carrier its chain books (None: driving power only)
        self.carrier_of = {(e if isinstance(e, str) else e.name):
                           (None if isinstance(e, str) else equation_carrier(e)) for e in equations}
        self.cache: dict[str, tuple] = {}
        self.energy_of = energy_vtype_of(equations)  # vtype_energy equation → its vType
        self.energy_mass = {e.name: e.mass_kg for e in equations if getattr(e, "name", None) in self.energy_of}
        #: vTypes resolved by other resolvers of the same run (Dask buckets of an FCD replay)
        self.seen: set[str] = set()
        #: vehicles not accounted because no equation is made for their vClass (by_vclass,
        #: by_vtype) or none books their energy carrier (by_carrier, when any: vClass → count)
        self.skipped: dict[str, dict[str, int]] = {"by_vclass": {}, "by_vtype": {}}
        #: vType → {"emission_class", "from", "carrier", "not_booked_by"}: chain equations
        #: made for the vType's vClass that book another energy carrier
        self.carriers: dict[str, dict] = {}
        #: vehicles left out by ``vehicles.vtypes``
        self.excluded = 0
        #: vType → {"vclass", "mass_kg", "source"} for masses taken from class defaults
        self.assumptions: dict[str, dict] = {}
        #: vType → {"vclass", "mass_kg"}: vTypes in no file read, at SUMO's mass (made during
        #: the run by TraCI, or loaded through SUMO options the plug-in does not read)
        self.sumo_masses: dict[str, dict] = {}
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
        ``default_carrier``."""
        present = {self.carrier_of[n] for n, a in zip(self.names, app) if a} - {None}
        if not present:
            return app
        ec = info.emission_class if info is not None else None
        carrier, src = energy_carrier(ec), "written"
        if carrier is None:  # none written, or a name of no known carrier
            if len(present) < 2 or not getattr(self.sc, "default_carrier", False):
                return app
            ec, src = self._default_emission_class(vt, vclass, written=ec is not None)
            carrier = energy_carrier(ec)
            if carrier is None:
                return app
        wrong = [i for i, n in enumerate(self.names) if app[i] and self.carrier_of[n] not in (None, carrier)]
        if wrong:
            app = app.copy()
            app[wrong] = 0.0
            self.carriers[vt] = {"emission_class": ec, "from": src, "carrier": carrier,
                                 "not_booked_by": [self.names[i] for i in wrong]}
        return app

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
            app = self._by_carrier(vt, info, body, app)
            if not app.any():
                return (np.nan, app, False, vclass, "carrier")
        if vt not in self.booked_as and vclass not in GENERIC_VCLASSES:
            body = vclass   # its own equations, so its own class's mass
        if body != vclass and cdata.get("mass_kg") is None:
            cdata = sc_classes.get(body, {})
        mass = data.get("mass_kg")
        if mass is None and info is not None:
            mass = info.mass_kg
        if mass is None:
            p = self._param(vt, "drvpw.mass")
            if p:
                try:
                    mass = float(p)
                except ValueError:
                    raise UserError(f"vType '{vt}': drvpw.mass is not a number: {p!r}") from None
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
        if mass is None:
            where = f" (defined in {info.source})" if info is not None else \
                " (not defined in the route/additional files: SUMO's default type?)"
            raise UserError(
                f"vType '{vt}' of vehicle '{vid}'{where} has no mass: give it a mass attribute, "
                f'a <param key="drvpw.mass" value="..."/>, or vtypes.{vt}.mass_kg or '
                f"vclasses.{vclass}.mass_kg in the scenario (or leave it out with vehicles.vtypes)")
        return (float(mass), app, True, vclass, "")


def run_scenario(scenario_path, out_dir=None, keep_vehicles: bool = False,
                 flush_vehicles: int | None = None, **overrides):
    """Run a scenario; returns its :class:`~sumo_drvpw.sim.outputs.RunResult` and writes
    its outputs into ``out_dir`` when given (``result["steps"]`` reads the summary).

    Parameters
    ----------
    scenario_path : scenario TOML file
    out_dir : output directory (created), or None to write nothing
    keep_vehicles : keep every vehicle in memory (default: vehicles that left are
        streamed out, :class:`~sumo_drvpw.sim.accountant.Accountant`)
    flush_vehicles : finished vehicles held before they are written out (default 1024)
    overrides : replace scenario values: begin, end, step_length [s], connection, gui,
        options, equations (names, paths or Equation objects), trace, edgedata, figures,
        progress, difference, period
    """
    from sumo_drvpw.sim.accountant import Accountant
    from sumo_drvpw.sim.loop import step_until
    from sumo_drvpw.sim.scenario import load_scenario

    sc = load_scenario(scenario_path, **overrides)
    if sc.trace and out_dir is None:
        raise UserError("outputs.trace needs an output directory")
    naming = _output_naming(sc)
    if out_dir is not None:
        Path(out_dir).mkdir(parents=True, exist_ok=True)
    args = list(sc.sumo_args)
    # the config's own outputs go into this run's output folder, not beside the scenario
    # (unless the scenario's options or the emissions comparison set them already)
    given = {a[2:] for a in args if a.startswith("--")}
    named = given | {a[2:].split("=", 1)[0] for a in args if a.startswith("--")}  # and --key=v
    if out_dir is not None:  # an output the scenario's options name by a relative path: into OUT/sumo/
        for i in range(len(args) - 1):
            files = [f.strip() for f in args[i + 1].split(",") if f.strip()]
            if (args[i].startswith("--") and is_output_option(args[i][2:]) and files
                    and not any(Path(f).is_absolute() for f in files)):
                args[i + 1] = sumo_output_args({args[i][2:]: args[i + 1]}, Path(out_dir) / SUMO_OUTPUT_DIR)[1]
    # the emissions comparison reads the config's own tripinfo (in OUT/sumo/) when it writes
    # one file; otherwise a tripinfo of its own, in a temporary folder, replacing the config's
    ti_cfg = "" if "tripinfo-output" in named else sc.config_outputs.get("tripinfo-output", "").strip()
    keep_ti = bool(sc.sumo_device and out_dir is not None and ti_cfg and "," not in ti_cfg)
    drop_ti = bool(sc.sumo_device and ti_cfg and not keep_ti)
    redirect = {k: v for k, v in sc.config_outputs.items()
                if k not in named and not (drop_ti and k == "tripinfo-output")}
    scratch = None
    import tempfile

    # outputs declared in additional files: into the same folder, through copies of those
    # files (SUMO writes them beside the file that declares them: the scenario's folder)
    copies = (tempfile.TemporaryDirectory(prefix=COPIES_PREFIX)
              if sc.additional_outputs and "additional-files" not in given else None)
    if redirect or sc.additional_outputs:
        if out_dir is not None:
            sumo_dir = Path(out_dir) / SUMO_OUTPUT_DIR
        else:
            scratch = tempfile.TemporaryDirectory(prefix="drvpw-sumo-outputs-")
            sumo_dir = Path(scratch.name)
        if redirect:
            args += sumo_output_args(redirect, sumo_dir)
    add_args, moved = ([], {}) if copies is None else redirect_additional_outputs(
        sc.additional_files, sumo_dir, Path(copies.name))
    for f in [sumo_dir / n for names in moved.values() for n in names]:
        prepare_output_folder(f, naming)  # a prefix's folder part: SUMO does not create it
    if add_args:  # sumo.additional, or the -a / --additional=F of sumo.options: loaded as the copies
        args = without_additional_files(args)
    args += add_args
    tmpdir, tripinfo = None, None
    if sc.sumo_device:  # SUMO's own model beside ours: its tripinfo, read after the run
        # the config's or the options' own device settings and tripinfo stay as they are
        # (SUMO refuses an option given twice)
        if not (sc.sumo_device_in_config or named & {"device.emissions.probability",
                                                      "device.emissions.explicit"}):
            args += ["--device.emissions.probability", "1"]
        ti_opt = _option_value(args, "tripinfo-output") if "tripinfo-output" in named else None
        if keep_ti:
            tripinfo = sumo_dir / Path(ti_cfg).name
        elif ti_opt:  # the options' tripinfo (already pointed into OUT/sumo/ when relative)
            tripinfo = Path(ti_opt.split(",")[0].strip())
        else:
            tmpdir = tempfile.TemporaryDirectory(prefix="drvpw-tripinfo-")
            tripinfo = Path(tmpdir.name) / "tripinfo.xml"
            args += ["--tripinfo-output", str(tripinfo), "--tripinfo-output.write-unfinished",
                     "true"]
    ours = {Path(d).resolve() for d in (scratch and scratch.name, tmpdir and tmpdir.name,
                                         out_dir is not None and Path(out_dir) / SUMO_OUTPUT_DIR) if d}
    for i in range(len(args) - 1):  # outputs sent into those folders: a prefix's folder part
        if args[i].startswith("--") and is_output_option(args[i][2:]):
            for f in args[i + 1].split(","):
                if f.strip() and Path(f.strip()).resolve().parent in ours:
                    prepare_output_folder(Path(f.strip()).resolve(), naming)
    from sumo_drvpw.sim.spill import SPILL_DIR, discard_parts, write_published

    # the route files' vTypes before SUMO reads them: a bad mass is named with its file and
    # vType here (SUMO's own refusal names neither); the Accountant books with them
    vtypes = read_vtypes([f for f in sc.route_files if Path(f).is_file()]) if sc.route_files else None
    conn = start_sumo(args, sc.connection, sc.gui)
    acc = None
    try:
        try:
            acc = Accountant(conn, scenario=sc, vtypes=vtypes,
                             trace_path=Path(out_dir) / "trace.parquet" if sc.trace else None,
                             keep_vehicles=keep_vehicles, flush_vehicles=flush_vehicles,
                             spill_dir=Path(out_dir) / SPILL_DIR if out_dir is not None else None)
            try:
                info = step_until(conn, acc.stepper, end=sc.end, progress=sc.progress,
                                  period=sc.period)
            except Exception as e:
                if type(e).__name__ in ("TraCIException", "FatalTraCIError"):
                    raise UserError(f"SUMO failed during the run: {e}") from None
                raise
            acc.interrupted = info["interrupted"]
            result = acc.result({"files": {"trace": "trace.parquet"}} if sc.trace else None)
        finally:
            if acc is not None:
                acc.close_trace()
            close_sumo(conn)
        check_vtype_filter(sc, acc.ledger)
        if tripinfo is not None:  # as SUMO named it (output-prefix, output-suffix)
            try:
                result.sumo_device = read_tripinfo_emissions(written_file(tripinfo, naming))
            finally:
                if tmpdir is not None:
                    tmpdir.cleanup()
            result.summary["sumo_device"] = result.sumo_device_comparison().to_dict("records")
        notes = []
        def written(names: list[str]) -> str:  # as SUMO named them, in OUT/sumo/
            return ", ".join(written_file(sumo_dir / n, naming).relative_to(sumo_dir).as_posix()
                             for n in names)

        if redirect and out_dir is not None:
            notes.append(f"SUMO outputs the config sets were written into {SUMO_OUTPUT_DIR}/: "
                         + ", ".join(f"{k} ({written([Path(f.strip()).name for f in v.split(',') if f.strip()])})"
                                     for k, v in redirect.items()))
        if drop_ti:
            notes.append("the config's tripinfo-output was replaced by the emissions comparison's "
                         "(outputs.sumo_device) and not kept")
        if moved and out_dir is not None:
            notes.append(f"outputs declared in additional files were written into "
                         f"{SUMO_OUTPUT_DIR}/: " + "; ".join(
                             f"{f}: {written(names)}" for f, names in moved.items()))
        elif sc.additional_outputs and not moved:
            notes.append("outputs declared in additional files were written by SUMO beside those "
                         "files: " + "; ".join(sc.additional_outputs))
        if notes:
            result.summary["warnings"] = list(result.summary.get("warnings", [])) + notes
        if out_dir is not None:
            write_published(result, out_dir)
    finally:  # the parts never stay in the output folder
        if acc is not None and out_dir is not None:
            discard_parts(acc.ledger)
        if scratch is not None:
            scratch.cleanup()
        if copies is not None:
            copies.cleanup()
    return result


def _option_value(args: list[str], key: str) -> str | None:
    """The value of ``--key`` in SUMO's command-line ``args`` (``--key v`` or ``--key=v``;
    the last one), or None."""
    val = None
    for i, a in enumerate(args):
        if a == f"--{key}" and i + 1 < len(args):
            val = args[i + 1]
        elif a.startswith(f"--{key}="):
            val = a.split("=", 1)[1]
    return val


def _output_naming(sc) -> dict[str, str]:
    """The output-prefix and output-suffix SUMO takes in this run (its options', else its
    config's); UserError when one would put the run's outputs outside OUT/sumo/."""
    from sumo_drvpw.sim.sumo_start import scenario_option

    naming = output_naming(lambda k: scenario_option(sc, k))
    key = naming_leaves_folder(naming)
    if key is not None:
        args = list(sc.sumo_args)
        where = (f"{sc.path or '<scenario>'}: sumo.options" if any(
            a == f"--{key}" or a.startswith(f"--{key}=") for a in args)
            else f"SUMO config {args[args.index('-c') + 1]}")
        raise UserError(f"{where}: {key} '{naming[key]}' leads out of the folder the run's SUMO "
                        f"outputs are written into ({SUMO_OUTPUT_DIR}/, '..'); give one without "
                        "'..' (a folder part names a folder inside it)")
    return naming


def read_tripinfo_emissions(path: Path):
    """Per vehicle SUMO's emissions-device totals from a tripinfo file: DataFrame vehicle,
    sumo_electricity_wh (Energy model) and sumo_fuel_mg (fuel models); plain or gzipped
    (a config's tripinfo-output named *.gz)."""
    import xml.etree.ElementTree as ET

    import pandas as pd

    from sumo_drvpw.fileio import open_maybe_gzip

    rows = []
    try:
        with open_maybe_gzip(path) as src:
            for _, el in ET.iterparse(src, events=("end",)):
                if el.tag == "tripinfo":
                    em = el.find("emissions")
                    if em is not None:
                        rows.append({"vehicle": el.get("id"),
                                     "sumo_electricity_wh": float(em.get("electricity_abs", "nan")),
                                     "sumo_fuel_mg": float(em.get("fuel_abs", "nan"))})
                    el.clear()
    except (ET.ParseError, OSError, EOFError) as e:
        raise UserError(f"SUMO tripinfo {path}: cannot read: {e}") from None
    return pd.DataFrame(rows, columns=["vehicle", "sumo_electricity_wh", "sumo_fuel_mg"])


def check_vtype_filter(sc, ledger) -> None:
    """Every vType named in ``vehicles.vtypes`` must have appeared in the run (else a typo
    would silently account nothing): UserError naming the missing ones."""
    if sc.vtype_filter is None:
        return
    seen = ledger.types_seen if hasattr(ledger, "types_seen") else set(ledger.veh_type)
    missing = [vt for vt in sc.vtype_filter if vt not in seen]
    if missing:
        raise UserError(f"{sc.path or '<scenario>'}: vehicles.vtypes names vType(s) "
                        f"{', '.join(missing)} that no vehicle of the run had "
                        f"(seen: {', '.join(sorted(seen)) or 'none'})")


#: One SUMO per process: libsumo is a process-wide singleton, so tasks of a Dask worker
#: with several threads take turns (run N at once with N single-threaded workers).
_ONE_SUMO = None


def _ignore_sigint() -> None:
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _sweep_task(scenario: str, out: str, overrides: dict, keep_vehicles: bool = False) -> dict:
    """One scenario, one SUMO, in this process (a pool or Dask worker); returns the summary."""
    import threading

    global _ONE_SUMO
    if _ONE_SUMO is None:
        _ONE_SUMO = threading.Lock()
    with _ONE_SUMO:
        return run_scenario(scenario, out, keep_vehicles=keep_vehicles, **overrides).summary


def run_scenarios(scenarios: list, out_dirs: list, overrides: dict | None = None,
                  engine: str = "local", jobs: int = 1, scheduler: str | None = None,
                  workers: int | None = None) -> list[dict]:
    """Run several scenarios (a sweep of scenarios or seeds), one SUMO process each; returns
    their summaries in the order given.

    Parameters
    ----------
    scenarios : scenario TOML files or built-in names
    out_dirs : one output folder per scenario (with ``dask`` on a cluster of other machines:
        on a filesystem the workers share)
    overrides : scenario values to replace in every run (as :func:`run_scenario`)
    engine : ``local`` (this machine: ``jobs`` processes) or ``dask`` (one task per
        scenario on a Dask cluster: ``scheduler`` address, else a local cluster of
        ``workers`` single-threaded processes)
    """
    from sumo_drvpw.sim.scenario import load_scenario
    from sumo_drvpw.sim.scenario_paths import scenario_path

    overrides = dict(overrides or {})
    paths = [str(scenario_path(s)) for s in scenarios]
    outs = [str(o) for o in out_dirs]
    for s in paths:  # every scenario checked before any runs: a bad one costs no good run
        load_scenario(s, **overrides)
    if engine == "local":
        if jobs <= 1:  # one after the other; an interrupted one (Ctrl-C) ends the sweep there
            done = []
            for s, o in zip(paths, outs):
                done.append(_sweep_task(s, o, overrides))
                if done[-1].get("interrupted"):
                    break
            return done
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor

        # spawn: each worker imports libsumo afresh (one simulation per process); the workers
        # leave Ctrl-C to this process, which stops them all at once on a signal (a worker
        # that dies breaks the pool: an error, not a wait)
        pool = ProcessPoolExecutor(max_workers=jobs, mp_context=mp.get_context("spawn"),
                                   initializer=_ignore_sigint)
        from concurrent.futures.process import BrokenProcessPool

        try:
            futs = [pool.submit(_sweep_task, s, o, overrides) for s, o in zip(paths, outs)]
            return [f.result() for f in futs]
        except BrokenProcessPool:
            raise UserError("a worker process of the sweep ended abruptly (killed, out of memory, or "
                            "SUMO crashed); nothing was written: run the scenarios one at a time to "
                            "see which") from None
        except BaseException:
            for proc in list(getattr(pool, "_processes", {}).values()):
                proc.terminate()
            raise
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
    if engine != "dask":
        raise UserError(f"engine '{engine}' unknown for SUMO runs; choose local or dask")
    # absolute: a worker's working folder is not ours
    paths = [str(Path(s).resolve()) for s in paths]
    outs = [str(Path(o).resolve()) for o in outs]
    from sumo_drvpw.fit.engine import dask_client, guarded, unguarded  # as the log engines

    with dask_client(scheduler, workers) as client:
        futs = [client.submit(guarded, _sweep_task, s, o, overrides, pure=False,
                              key=f"sumo-run-{k}-{Path(s).stem}")
                for k, (s, o) in enumerate(zip(paths, outs))]
        out = []
        for f in futs:  # in the order given; a failed run raises its error here
            out.append(unguarded(f.result()))
            f.release()
        return out
