"""SUMO's own outputs of a run: the output options a SUMO config sets and the outputs its
additional files declare, sent into the run's output folder (``OUT/sumo/``) instead of
beside the scenario's files (inputs are never modified; a read-only scenario runs too)."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
import zlib
from pathlib import Path

from sumo_drvpw.errors import UserError
from sumo_drvpw.fileio import open_maybe_gzip

#: how deep ``<include href>`` is followed in SUMO's XML inputs (SUMO's own loader has no
#: limit; a cycle would have none either)
INCLUDE_DEPTH = 10

#: SUMO options that name an output file but do not end in "-output"
_OUTPUT_OPTIONS = {"log", "message-log", "error-log", "summary", "netstate-dump", "ndump",
                   "save-state.files", "save-configuration", "save-template"}
#: additional-file elements whose ``file`` attribute is an output SUMO writes (relative to
#: the additional file)
_OUTPUT_ELEMENTS = {"edgeData", "laneData", "e1Detector", "inductionLoop", "e2Detector",
                    "laneAreaDetector", "e3Detector", "entryExitDetector", "instantInductionLoop",
                    "routeProbe", "vTypeProbe", "edgeRelations", "tazRelations", "meanData"}
#: … and elements naming their output in another attribute
_OUTPUT_ATTRS = {"calibrator": "output", "timedEvent": "dest"}


def output_attribute(tag: str) -> str | None:
    """The attribute of an additional-file element (tag without namespace) that names an
    output file SUMO writes, or None."""
    return "file" if tag in _OUTPUT_ELEMENTS else _OUTPUT_ATTRS.get(tag)


def is_output_option(key: str) -> bool:
    """Whether a SUMO option names an output file (``tripinfo-output``, ``log`` …)."""
    return key.endswith("-output") or key in _OUTPUT_OPTIONS


def additional_elements(paths, depth: int = 0):
    """Every element of SUMO XML files ``paths`` and of the files they ``<include href>``
    (to :data:`INCLUDE_DEPTH`), as (file, element) at the element's end, an include's
    elements where it stands; each element is cleared once the caller moves on. A file that
    cannot be read or parsed (a truncated .gz among them) is passed over: SUMO reports it."""
    for p in paths:
        try:
            with open_maybe_gzip(p) as src:
                for _, el in ET.iterparse(src, events=("end",)):
                    if el.tag.split("}")[-1] == "include" and el.get("href") and depth < INCLUDE_DEPTH:
                        yield from additional_elements([Path(p).parent / el.get("href")], depth + 1)
                    else:
                        yield p, el
                    el.clear()
        except (ET.ParseError, OSError, EOFError, zlib.error):
            continue


def additional_outputs(paths) -> list[str]:
    """Outputs the additional files declare (``edgeData id='x' file='y'`` …), theirs and
    those of the files they ``<include href>``, as 'FILE: element id → output' lines; SUMO
    writes them beside the file that declares them."""
    found = []
    for p, el in additional_elements(paths):
        tag = el.tag.split("}")[-1]
        key = output_attribute(tag)
        if key and el.get(key):
            found.append(f"{p}: {tag} '{el.get('id', '')}' → {el.get(key)}")
    return found


#: subfolder of a run's output folder for the outputs its SUMO config sets
SUMO_OUTPUT_DIR = "sumo"


def sumo_output_args(outputs: dict[str, str], folder: Path) -> list[str]:
    """Command-line options sending each output a SUMO config sets (option → file(s) as
    written there) into ``folder`` under its own file name (the command line overrides
    the config; ``folder`` is created)."""
    folder.mkdir(parents=True, exist_ok=True)
    args = []
    for key, val in outputs.items():
        names = [Path(v.strip()).name for v in val.split(",") if v.strip()]
        args += [f"--{key}", ",".join(str(folder.resolve() / n) for n in names)]
    return args


#: attributes of additional-file elements that name an input file, relative to that file
_INPUT_PATH_ATTRIBUTES = ("file", "href", "edgesFile", "imgFile")


#: the temporary folder of a run's copies of its additional files (:func:`redirect_additional_outputs`),
#: each named ``<n>.<original name>``: an FCD the run recorded names them in its header
COPIES_PREFIX = "drvpw-additional-"


def original_of_copy(path: str) -> str | None:
    """The original file name of a run's copy of an additional file named in a recording's
    header (``…/drvpw-additional-XXXX/0.stops.add.xml`` → ``stops.add.xml``); None for any
    other path."""
    parts = path.replace("\\", "/").split("/")
    m = re.match(r"^\d+\.(.+)$", parts[-1])
    return m.group(1) if m and len(parts) > 1 and parts[-2].startswith(COPIES_PREFIX) else None


def redirect_additional_outputs(adds: list[Path], folder: Path, work: Path
                                ) -> tuple[list[str], dict[str, list[str]]]:
    """Copies of the additional files that declare outputs (``edgeData file=…``, detectors
    …; themselves or in a file they ``<include href>``), written into ``work``, whose
    outputs go into ``folder`` under their own file names (declarations of the same file
    write one file, as SUMO's do; two different files of the same name: the second gets
    the declaring file's name before it) and whose other relative paths (inputs such
    as a rerouter's ``file``) point at the original files. Returns the command-line options
    loading the copies instead of the originals (``--additional-files``; none when nothing
    is declared) and the outputs moved, per declaring file (its output names). The
    originals are not touched."""
    moved: dict[str, list[str]] = {}
    used: set[str] = set()
    names: dict[Path, str] = {}  # output file as declared (resolved) → its name in ``folder``
    copies: dict[Path, Path] = {}

    def load(add: Path, depth: int) -> Path:
        """The file SUMO should load for ``add``: a copy when outputs are declared in it
        or in what it includes, else the original."""
        add = add.resolve()
        if add in copies:
            return copies[add]
        try:
            with open_maybe_gzip(add) as src:
                tree = ET.parse(src)
        except (ET.ParseError, OSError):
            return add  # SUMO reports an unreadable additional file itself
        changed = False
        for el in tree.iter():
            tag = el.tag.split("}")[-1]
            key = output_attribute(tag)
            if key and el.get(key):
                orig = (add.parent / el.get(key)).resolve()
                name = names.get(orig)
                if name is None:  # a file several declarations share stays one file
                    name = base = Path(el.get(key)).name
                    k = 1
                    while name in used:
                        name = f"{add.name.split('.')[0]}.{base}" if k == 1 else \
                            f"{add.name.split('.')[0]}.{k}.{base}"
                        k += 1
                    used.add(name)
                    names[orig] = name
                if name not in moved.get(str(add), []):
                    moved.setdefault(str(add), []).append(name)
                el.set(key, str(folder.resolve() / name))
                changed = True
            elif tag == "include" and el.get("href") and depth < INCLUDE_DEPTH:
                target = add.parent / el.get("href")
                got = load(target, depth + 1)
                changed |= got != target.resolve()
                el.set("href", str(got))
            else:  # inputs by relative path (a rerouter's file, …): to the original's folder
                for key in _INPUT_PATH_ATTRIBUTES:
                    val = el.get(key)
                    if val and not Path(val).is_absolute():
                        el.set(key, str((add.parent / val).resolve()))
        if not changed:
            return add
        folder.mkdir(parents=True, exist_ok=True)
        copy = work / f"{len(copies)}.{add.name.removesuffix('.gz')}"
        tree.write(copy, encoding="utf-8", xml_declaration=True)
        copies[add] = copy
        return copy

    loaded = [str(load(Path(a), 0)) for a in adds]
    if not moved:
        return [], {}
    return ["--additional-files", ",".join(loaded)], moved


# ------------------------------------------------- SUMO's output-prefix and output-suffix
#: the options that rename every output file SUMO writes (SUMO 1.28)
NAMING_OPTIONS = ("output-prefix", "output-suffix")
#: what SUMO puts for the first "TIME" in either: the time its options were loaded
#: (OutputDevice::getDevice: OptionsIO::getLoadTime, strftime "%Y-%m-%d-%H-%M-%S")
_STAMP_GLOB = "-".join(["[0-9]" * 4] + ["[0-9]" * 2] * 5)
#: an extension SUMO's output-suffix goes before has at most this many characters
_SUFFIX_EXT_MAX = 4


def output_naming(option) -> dict[str, str]:
    """The output-prefix and output-suffix a run's SUMO takes (``option``: key → the value
    the scenario's options or its config give, or None; sumo_start.scenario_option);
    only those that are set and not empty."""
    return {k: v for k in NAMING_OPTIONS if (v := option(k))}


def sumo_file_name(path: str, naming: dict[str, str], stamp: str = "TIME") -> str:
    """The file SUMO writes for an output it is told to write to ``path``, given
    ``output_naming``; its first "TIME" (in either) becomes ``stamp``.

    The prefix goes before the path's last component, as SUMO does it
    (OutputDevice::getDevice → FileHelpers::prependToLastPathComponent, eclipse-sumo/sumo
    src/utils/iodevices/OutputDevice.cpp, utils/common/FileHelpers.cpp): "run1_" turns
    ``d/ti.xml`` into ``d/run1_ti.xml``, and a prefix with a folder part ("res/run1_")
    names a folder below the output's (``d/res/run1_ti.xml``), which SUMO does not create.
    The suffix then goes before the extensions of up to four characters each that end the
    (prefixed) last component ("_S": ``ti.xml.gz`` → ``ti_S.xml.gz``, ``a.longpart.xml`` →
    ``a.longpart_S.xml``, with prefix "P.1_" ``a.b.xml`` → ``P_S.1_a.b.xml``), at its end
    when there is none (``ns.parquet`` → ``ns.parquet_S``) — as SUMO 1.28 writes them
    (tests/test_sim_sumo_names.py runs it)."""
    def split(p: str) -> tuple[str, str]:
        cut = max(p.rfind("/"), p.rfind("\\")) + 1
        return p[:cut], p[cut:]

    head, name = split(path)
    head, name = split(head + naming.get("output-prefix", "").replace("TIME", stamp, 1) + name)
    suffix = naming.get("output-suffix", "").replace("TIME", stamp, 1)
    if suffix:
        stem = name
        while "." in stem and len(stem.rsplit(".", 1)[1]) <= _SUFFIX_EXT_MAX:
            stem = stem.rsplit(".", 1)[0]
        name = stem + suffix + name[len(stem):]
    return head + name


def naming_leaves_folder(naming: dict[str, str]) -> str | None:
    """The first of output-prefix and output-suffix whose folder part leads out of the
    folder an output is written into (``../``: SUMO would write the run's outputs outside
    ``OUT/sumo/``), or None. An absolute prefix stays inside: SUMO puts it after the
    output's folder (``d/`` + ``/x/`` = ``d//x/``)."""
    import posixpath

    for key, val in naming.items():
        probe = posixpath.normpath("d/" + sumo_file_name("x", {key: val}).replace("\\", "/"))
        if not probe.startswith("d/"):
            return key
    return None


def prepare_output_folder(path: Path, naming: dict[str, str]) -> None:
    """Create the folder SUMO writes the output ``path`` into (a prefix's folder part
    names one below ``path``'s, which SUMO does not create); one named by "TIME" is left
    to SUMO."""
    target = Path(sumo_file_name(str(path), naming))
    if target.parent == Path(sumo_file_name(str(path), naming, "\0")).parent:
        target.parent.mkdir(parents=True, exist_ok=True)


def written_file(path: Path, naming: dict[str, str]) -> Path:
    """The file SUMO wrote for an output it was told to write to ``path``: its name as
    :func:`sumo_file_name` has it ("TIME" matched against what is there, the newest if
    several), or ``path`` itself when only that is there (SUMO opens some files without
    the prefix: OutputDevice::getDevice's usePrefix); the renamed name when neither is."""
    import glob

    target = Path(sumo_file_name(str(path), naming))
    mark = "\0"
    if sumo_file_name(str(path), naming, mark) != str(target):  # TIME in either
        pattern = glob.escape(sumo_file_name(str(path), naming, mark)).replace(mark, _STAMP_GLOB)
        found = sorted(glob.glob(pattern))
        if found:
            return Path(found[-1])
    return path if not target.exists() and path.exists() else target


def option_input_files(args: list, routes: list[Path], adds: list[Path]) -> tuple[list[Path], list[Path]]:
    """The route and additional files SUMO loads with the command line ``args`` (a config's
    ``routes`` and ``adds`` as read from it): a later ``-r``/``--route-files`` replaces the
    route files, ``-a``/``--additional-files`` the additional files, as SUMO's command line
    overrides its config (paths relative to the working directory). Returns (routes, then
    additional files; the additional files alone): a scenario's ``sumo.options`` then give
    the vTypes, stops, params and the outputs additional files declare.
    SUMO's forms: ``-r F``, ``--route-files F``, ``--route-files=F`` (``-r=F``) and the
    synonyms ``--routes`` and ``--additional``."""
    it = iter(args)
    for a in it:
        name, eq, value = str(a).partition("=") if str(a).startswith("-") else (a, "", "")
        if name in ROUTE_OPTIONS + ADDITIONAL_OPTIONS:
            given = [Path(f.strip()).resolve() for f in str(value if eq else next(it, "")).split(",")
                     if f.strip()]
            if name in ROUTE_OPTIONS:
                routes = given
            else:
                adds = given
    return [*routes, *adds], adds


def without_additional_files(args: list) -> list:
    """``args`` without their additional files (``-a F``, ``--additional-files=F``, …: every
    form of :data:`ADDITIONAL_OPTIONS`), for copies of those files to be given instead
    (SUMO refuses an option given twice on its command line)."""
    out, skip = [], False
    for a in args:
        if skip:
            skip = False
        elif str(a).startswith("-") and str(a).partition("=")[0] in ADDITIONAL_OPTIONS:
            skip = "=" not in str(a)
        else:
            out.append(a)
    return out


#: SUMO's names of its route-files and additional-files options (synonyms included)
ROUTE_OPTIONS = ("-r", "--route-files", "--routes")
ADDITIONAL_OPTIONS = ("-a", "--additional-files", "--additional")


def device_wanted(wanted: bool, on: bool, given: dict[str, str], where: str) -> bool:
    """``outputs.sumo_device`` as the scenario sets it (``wanted``), refused when the run's
    SUMO options ``given`` (option → value: device.emissions.probability, .explicit) switch
    SUMO's emissions device off for every vehicle (``on`` False: probability 0, no explicit
    vehicle): the run keeps the options' device setting as given (SUMO refuses an option
    twice) and would write an empty ``sumo_device.csv``. A UserError naming the option."""
    if wanted and given and not on:
        opts = ", ".join(f"--{k} {v!r}" for k, v in given.items())
        raise UserError(f"{where}: outputs.sumo_device = true, but the SUMO options set {opts}: SUMO's "
                        "emissions device is off for every vehicle and sumo_device.csv would be empty; "
                        "drop the option (or give a probability > 0) or set outputs.sumo_device = false")
    return wanted


#: sumo_device.csv's columns
DEVICE_COLUMNS = ["equation", "quantity", "vehicles", "ours", "sumo", "ratio",
                  "ours_auxiliary", "ratio_auxiliary", "ratio_rest", "note"]

#: what a battery chain's row compares (docs/scenario.md, "SUMO's emissions device beside ours")
BATTERY_NOTE = ("model difference, not a booking one: SUMO's Energy model takes the vType's mass, "
                "frontSurfaceArea·airDragCoefficient, rollDragCoefficient (default 0.01), "
                "constantPowerIntake (default 100 W, booked standing too) and efficiencies "
                "(defaults 0.98/0.96, no recuperation limit); ours the vType's mass with the "
                "equation's calibrated road load and its chain's efficiencies, recuperation limit "
                "and auxiliary power (ratio_auxiliary: our auxiliary energy over SUMO's total; "
                "ratio_rest: the remainder)")

#: what the row of a ``vtype_energy`` equation compares (sim/vtype_energy.py)
OWN_PARAMS_NOTE = ("like for like: the vType's own Energy-model parameters (SUMO's defaults for those it "
                   "leaves out) as terms and a battery chain, its radial drag in curves as SUMO books it "
                   "per step at SUMO's slope of the vehicle; SUMO's emissions device books a trip's last steps otherwise "
                   "than its own emission output (a few % of a short trip, docs/scenario.md); a bus dwelling "
                   "in a bay (a busStop with parking=\"true\") is off its lane for SUMO, which books nothing "
                   "there, where ours books it standing with its constantPowerIntake (an e-bus line: several %) "
                   "(summary.json assumptions.vtype_energy)")

#: what a full hybrid's fuel-chain row compares: SUMO's device books the car as a conventional engine
HYBRID_NOTE = ("model difference: SUMO has no full-hybrid car class, so its emissions device books the "
               "vType's emissionClass as HBEFA or PHEMlight gives it (a plug-in hybrid's petrol share "
               "(P) or a petrol car: the engine runs as a conventional one's), while this chain's engine "
               "is off at rest and at light load, the battery driving and the braking energy recovered: "
               "the ratio holds a full hybrid's saving (the EPA lists' full hybrids burn 33-56 % less "
               "than their petrol twins in town, docs/epa-hybrid.md)")
#: a plug-in hybrid's row ([chain.depleting], model/chain_plugin.py): its litres begin after its battery
PLUG_IN_NOTE = ("model difference: SUMO's emissions device books a plug-in hybrid's petrol share (P) as a "
                "conventional engine's from the departure, while this chain drives each vehicle on its charged "
                "battery until the usable energy is spent, burning no fuel, then as a full hybrid (engine off at "
                "rest and at light load): the ratio holds the battery's trips and a full hybrid's saving; its "
                "battery kWh are in chain_vehicles.csv (docs/energy-chain.md)")
#: and a hybrid bus's row (its vehicles of these vClasses): SUMO's class is a hybrid's
HYBRID_BUS_VCLASSES = ("bus", "coach")
HYBRID_BUS_NOTE = ("model difference: SUMO's emissions device books the vType's emissionClass — for a hybrid "
                   "bus HBEFA 4's UBus_…_HEV_…, a function of speed and acceleration that burns about as much as "
                   "its diesel twin in town "
                   "(more on the WLTC's low phase, docs/hdv-hybrid.md), while this chain is the diesel bus's "
                   "with its engine off at rest and its braking energy given back (NREL measured hybrid buses "
                   "33-43 % below diesel ones on slow bus cycles): the ratio holds that difference")
EXPORTED_NOTE = ("like for like: these vehicles' vType is this equation's own export (sumo-drvpw "
                 "export-vtype: its road load as SUMO's Energy model, efficiencies 1, no constant intake), "
                 "so SUMO's electricity is the same net driving energy at the wheels; the slopes' source "
                 "and a trip's last steps differ (docs/scenario.md)")


def exported_vtypes(file_vtypes: dict) -> dict[str, set]:
    """Equation name → the vTypes that are its export (``drvpw.equation`` names it, SUMO's
    Energy model with efficiencies 1 and no constant intake, as export-vtype writes an
    equation without a chain)."""
    out: dict[str, set] = {}
    for vt, info in (file_vtypes or {}).items():
        p = getattr(info, "energy_params", None) or {}
        try:
            plain = (float(p.get("propulsionEfficiency", "nan")) == 1.0
                     and float(p.get("recuperationEfficiency", "nan")) == 1.0
                     and float(p.get("constantPowerIntake", "nan")) == 0.0)
        except ValueError:
            plain = False
        if plain and getattr(info, "equation", None) and str(info.emission_class or "").startswith("Energy"):
            out.setdefault(info.equation, set()).add(vt)
    return out


#: what the row of an equation without an energy chain compares (an electric bus: no battery
#: chain applies to buses); its ratio is no verdict on the equation
NO_CHAIN_NOTE = ("not like for like: this equation has no energy chain (another equation's may book "
                 "these vehicles), so its figure is the "
                 "equation's net driving energy at the wheels (traction less all recuperable "
                 "braking energy: no drivetrain or recuperation efficiencies, recuperation limit "
                 "or auxiliary power); SUMO's electricity adds its model's efficiencies "
                 "(propulsionEfficiency, recuperationEfficiency; defaults 0.98/0.96) and "
                 "constantPowerIntake (default 100 W, booked standing too) to the vType's road "
                 "load: the ratio checks the road load only against a vType with efficiencies 1 "
                 "and no intake (sumo-drvpw export-vtype); otherwise SUMO's losses and "
                 "auxiliaries, which ours leaves out, lower it")


def energy_default_masses(file_vtypes: dict, default_masses: dict) -> dict[str, tuple[float, float]]:
    """vType → (SUMO's mass, ours) [kg] of the vTypes SUMO runs on its Energy model at its
    default mass (a written ``Energy``/``Energy/…`` class and no mass: 1830 kg, whatever the
    vClass) while the run booked them at a class default (``default_masses``: vType → its
    summary.json assumption, with ``mass_kg``)."""
    from sumo_drvpw.model.energy_params import SUMO_DEFAULTS
    from sumo_drvpw.sim.vtype_energy import is_energy_class

    return {vt: (SUMO_DEFAULTS["mass"], float(d["mass_kg"])) for vt, d in (default_masses or {}).items()
            if vt in (file_vtypes or {}) and is_energy_class(getattr(file_vtypes[vt], "emission_class", None))
            and float(d["mass_kg"]) != SUMO_DEFAULTS["mass"]}


def device_inputs(file_vtypes: dict, default_masses: dict) -> tuple[dict, dict]:
    """What :func:`device_comparison` reads of a run's vTypes: :func:`exported_vtypes` and
    :func:`energy_default_masses`."""
    return exported_vtypes(file_vtypes), energy_default_masses(file_vtypes, default_masses)


def device_comparison(v, dev, cv, chains: dict, exported: dict | None = None, masses: dict | None = None):
    """Per equation, over the vehicles SUMO's emissions device reports for (``dev``: vehicle,
    sumo_electricity_wh, sumo_fuel_mg), what the plug-in books beside what SUMO's own model
    books: an equation with a battery chain its battery kWh against SUMO's electricity; with
    a fuel chain its litres against SUMO's fuel (mg, in litres at the chain fuel's density);
    an equation without a chain its net driving energy at the wheel (``v``: vehicle,
    equation, net_total_j) against SUMO's electricity, with :data:`NO_CHAIN_NOTE`. ``cv``: the chains' per-vehicle rows
    (vehicle, equation, net_kwh, auxiliary_kwh, fuel_l), or None; ``chains``: name → chain;
    ``exported``: equation → the vTypes that are its export (:func:`exported_vtypes`; ``v``
    then with a vtype column): a row whose vehicles all drive one is like for like;
    ``masses``: :func:`energy_default_masses`, named in the note of an electricity row whose
    vehicles drive such a vType (SUMO's electricity is then at another mass than ours).

    A battery chain's ratio is split additively: ``ratio_auxiliary`` = our auxiliary energy
    (``ours_auxiliary`` kWh: the chain's constant, HVAC and cabin warm-up, standing and
    moving) over SUMO's total, ``ratio_rest`` = the rest of ours (traction less recuperation)
    over SUMO's total; SUMO's own total holds its constantPowerIntake, which its output does
    not separate."""
    import pandas as pd

    from sumo_drvpw.model.constants import FUELS

    rows = []
    if dev is None:
        return pd.DataFrame(rows, columns=DEVICE_COLUMNS)
    v = v.merge(dev, on="vehicle", how="inner")
    if cv is not None and {"vehicle", "equation"} <= set(cv.columns):  # (none: no vehicle)
        cols = [c for c in ("vehicle", "equation", "net_kwh", "auxiliary_kwh", "fuel_l")
                if c in cv.columns]
        v = v.merge(cv[cols], on=["vehicle", "equation"], how="left")
    nan = float("nan")
    for eq, g in v.groupby("equation", sort=False):
        c = chains.get(eq)
        aux, note = nan, ""
        if c is not None and c.predicts == "fuel" and "sumo_fuel_ml" in g:  # emissions.volumetric-fuel
            g = g[g.sumo_fuel_ml.abs() > 0]
            ours, sumo, q = g.fuel_l.sum(), g.sumo_fuel_ml.sum() / 1e3, "fuel L (chain; SUMO's volumetric fuel)"
        elif c is not None and c.predicts == "fuel":
            g = g[g.sumo_fuel_mg.abs() > 0]
            dens = FUELS[c.fuel]["density_kg_per_l"]
            ours, sumo = g.fuel_l.sum(), g.sumo_fuel_mg.sum() / 1e6 / dens
            q = f"fuel L (chain; SUMO's fuel mass at {dens:g} kg/L)"
        if c is not None and c.predicts == "fuel":
            if c.charge_sustaining and c.engine_off_below_w > 0:  # a full hybrid's (sim/carrier.is_hybrid_chain)
                bus = "vclass" in g and len(g) and g.vclass.isin(HYBRID_BUS_VCLASSES).all()
                note = HYBRID_BUS_NOTE if bus else HYBRID_NOTE  # (what SUMO books: its class's)
                note = PLUG_IN_NOTE if c.depleting is not None else note
        else:
            g = g[g.sumo_electricity_wh.abs() > 0]
            sumo = g.sumo_electricity_wh.sum() / 1e3
            if c is not None:
                ours, q = g.net_kwh.sum(), "battery kWh (chain)"
                aux, note = float(g.auxiliary_kwh.sum()), BATTERY_NOTE
                if (getattr(c, "provenance", None) or {}).get("sumo_energy_model"):
                    note = OWN_PARAMS_NOTE
            else:
                ours, q = g.net_total_j.sum() / 3.6e6, "net driving energy kWh (no chain)"
                own = (exported or {}).get(eq)
                note = EXPORTED_NOTE if own and "vtype" in g and set(g.vtype) <= own else NO_CHAIN_NOTE
        fuel = c is not None and c.predicts == "fuel"
        diff = sorted(set(g.vtype) & set(masses or {})) if "vtype" in g and not fuel else []
        if diff:
            note += ("; masses differ: SUMO's Energy model runs " + ", ".join(
                f"{vt} at its default {masses[vt][0]:g} kg (the vType writes none), ours {masses[vt][1]:g} kg"
                for vt in diff) + " (summary.json assumptions.default_masses)")
        if len(g):
            ok = bool(sumo) and aux == aux
            rows.append({"equation": eq, "quantity": q, "vehicles": int(len(g)),
                         "ours": float(ours), "sumo": float(sumo),
                         "ratio": float(ours / sumo) if sumo else nan,
                         "ours_auxiliary": aux,
                         "ratio_auxiliary": aux / sumo if ok else nan,
                         "ratio_rest": (float(ours) - aux) / sumo if ok else nan, "note": note})
    return pd.DataFrame(rows, columns=DEVICE_COLUMNS)
