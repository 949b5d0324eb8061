"""Run a scenario: start SUMO, resolve vTypes, step the loop, write the outputs.

``run_scenario(scenario_path, out_dir, **overrides) -> RunResult`` runs a scenario file
(see :mod:`sumo_drvpw.sim.scenario`) with libsumo (or traci) and writes the outputs of
:mod:`sumo_drvpw.sim.outputs` into ``out_dir``. Modules: ``scenario`` (config), ``vtypes``
(mass and drvpw.* params from the route files), ``resolver`` (which equations book a vType,
at what mass), ``network`` (edge table, classes, robust
slopes), ``ledger`` (vectorized evaluation and accumulation), ``loop`` (the stepping loop,
connection passed in), ``sumo_start`` (starting SUMO), ``outputs``, ``sumo_outputs`` (SUMO's own outputs into ``OUT/sumo/``).
"""

from __future__ import annotations

from pathlib import Path

from sumo_drvpw.errors import UserError
from sumo_drvpw.sim.sumo_start import close_sumo, start_sumo
from sumo_drvpw.sim.resolver import VTypeResolver
from sumo_drvpw.sim.vtypes import SUMO_DEFAULT_VTYPES, read_vtypes
from sumo_drvpw.sim.sumo_outputs import (COPIES_PREFIX, SUMO_OUTPUT_DIR, is_output_option, naming_leaves_folder,
                                         output_naming, prepare_output_folder,
                                         redirect_additional_outputs, sumo_output_args, without_additional_files,
                                         written_file)

__all__ = ["run_scenario", "start_sumo", "close_sumo", "VTypeResolver"]


def check_vtype_tables(sc, vtypes) -> None:
    """A scenario's ``[vtypes.<id>]`` that names no vType of the route and additional files the
    run loads, nor one of SUMO's own: refused before SUMO starts, with the nearest id (a typo
    would leave the vType's vehicles on the defaults); one naming a vTypeDistribution too (its
    vehicles take its members' ids: its settings would book none); a vehicle's own copy
    (``<type>@<id>``) given more than its ``mass_kg`` (its equations and cold start are its type's)."""
    if vtypes is None or not getattr(sc, "vtype_data", None):
        return
    import difflib

    known = set(vtypes) | set(SUMO_DEFAULT_VTYPES)
    for vt in sc.vtype_data:
        if vt in getattr(vtypes, "distributions", ()) and vt not in vtypes:
            raise UserError(f"{sc.path or 'the scenario'}: [vtypes.{vt}] names a vTypeDistribution: its vehicles "
                            "take its members' vType ids, so its settings would book none; give them per member "
                            "([vtypes.<member>])")
        if vt not in known and vt.rpartition("@")[0] not in known:  # (a vehicle's own copy: <type>@<id>)
            near = difflib.get_close_matches(vt, sorted(known), n=1)
            raise UserError(f"{sc.path or 'the scenario'}: [vtypes.{vt}] names no vType of the route and "
                            f"additional files the run loads" + (f" (did you mean '{near[0]}'?)" if near else "")
                            + f"; their vTypes: {_listed(sorted(set(vtypes) | set(getattr(vtypes, 'distributions', ()))))}")
        other = sorted(set(sc.vtype_data[vt]) - {"mass_kg"}) if vt not in known else []
        if other:  # a copy keeps its type's resolution (sim/loop.py check_types): only its mass is its own
            raise UserError(f"{sc.path or 'the scenario'}: [vtypes.{vt}] is a vehicle's own vType copy (<type>@<id>): "
                            f"it takes mass_kg only — its vehicle keeps [vtypes.{vt.rpartition('@')[0]}]'s equations "
                            f"and cold start — got {', '.join(other)}")


def _listed(ids: list[str], most: int = 12) -> str:
    return (", ".join(ids[:most]) + (f" … ({len(ids)} in all)" if len(ids) > most else "")) or "none"


def run_scenario(scenario_path, out_dir=None, keep_vehicles: bool = False,
                 flush_vehicles: int | None = None, force: bool = False, **overrides):
    """Run a scenario; returns its :class:`~sumo_drvpw.sim.outputs.RunResult` and writes
    its outputs into ``out_dir`` when given (``result["steps"]`` reads the summary).

    Parameters
    ----------
    scenario_path : scenario TOML file or SUMO config, or a built-in scenario's name
        (``"city"``, ``"highway"``), as ``sumo-drvpw run`` takes it
    out_dir : output directory (created), or None to write nothing; written as a whole set with
        its manifest.json, as the commands write theirs: an earlier set's files there that the
        run does not write again are removed once it is written (a run refused or failed
        leaves the earlier set), and a folder that holds other files is refused unless ``force``
    keep_vehicles : keep every vehicle in memory (default: vehicles that left are
        streamed out, :class:`~sumo_drvpw.sim.accountant.Accountant`)
    flush_vehicles : finished vehicles held before they are written out (default 1024)
    force : write into ``out_dir`` though it holds files of the user's (they are kept)
    overrides : replace scenario values (every key of ``sumo_drvpw.sim.scenario.OVERRIDES``):
        begin, end, step_length [s], connection, gui, options, equations (names, paths or
        Equation objects; one alone too), trace, edgedata, figures, progress, difference,
        period, air_temperature_c, cold_start, and the reading settings
    """
    from sumo_drvpw.sim.accountant import Accountant
    from sumo_drvpw.sim.stepping import step_until
    from sumo_drvpw.sim.scenario import load_scenario
    from sumo_drvpw.sim.scenario_paths import scenario_path as file_of

    sc = load_scenario(file_of(scenario_path), **overrides)  # (a built-in's name too, as `run` takes it)
    if sc.trace and out_dir is None:
        raise UserError("outputs.trace needs an output directory")
    naming = _output_naming(sc)

    from sumo_drvpw.fileio import check_earlier_set, earlier_stamps, in_output_set, remove_stale, write_manifest

    standalone = out_dir is not None and not in_output_set(out_dir)  # (a command writes its set whole)
    # (the Python API: an earlier set's files not written again go once the run is written)
    listed, kept = check_earlier_set(out_dir, force) if standalone else ([], [])
    stamps = earlier_stamps(out_dir, listed) if standalone else {}
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
    copies = tempfile.TemporaryDirectory(prefix=COPIES_PREFIX) if sc.additional_outputs else None
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
    check_vtype_tables(sc, vtypes)
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
                                  period=sc.period, period_from=sc.period_from)
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
                from sumo_drvpw.sim.sumo_start import scenario_option
                from sumo_drvpw.sim.vtypes import is_true
                result.sumo_device = read_tripinfo_emissions(  # (fuel in ml with emissions.volumetric-fuel)
                    written_file(tripinfo, naming), is_true(scenario_option(sc, "emissions.volumetric-fuel")))
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
        if standalone:
            discard_parts(acc.ledger)
            remove_stale(out_dir, stamps)
            write_manifest(Path(out_dir), command=["run_scenario", str(scenario_path)], kept=kept)
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


def read_tripinfo_emissions(path: Path, volumetric: bool = False):
    """Per vehicle SUMO's emissions-device totals from a tripinfo file: DataFrame vehicle,
    sumo_electricity_wh (Energy model) and sumo_fuel_mg (fuel models) — sumo_fuel_ml in its
    place when the run set ``emissions.volumetric-fuel`` (SUMO 1.28 then writes ``fuel_abs``
    in ml); plain or gzipped (a config's tripinfo-output named *.gz)."""
    import xml.etree.ElementTree as ET

    import pandas as pd

    from sumo_drvpw.fileio import open_maybe_gzip

    rows, fuel = [], "sumo_fuel_ml" if volumetric else "sumo_fuel_mg"
    try:
        with open_maybe_gzip(path) as src:
            for _, el in ET.iterparse(src, events=("end",)):
                if el.tag == "tripinfo":
                    em = el.find("emissions")
                    if em is not None:
                        rows.append({"vehicle": el.get("id"),
                                     "sumo_electricity_wh": float(em.get("electricity_abs", "nan")),
                                     fuel: float(em.get("fuel_abs", "nan"))})
                    el.clear()
    except (ET.ParseError, OSError, EOFError) as e:
        raise UserError(f"SUMO tripinfo {path}: cannot read: {e}") from None
    return pd.DataFrame(rows, columns=["vehicle", "sumo_electricity_wh", fuel])


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
