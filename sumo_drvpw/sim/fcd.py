"""Book a finished simulation from SUMO's FCD output, through the same ledger as ``run``.

``process_fcd(fcd_file, net=..., scenario=..., out_dir=...) -> RunResult`` reads an FCD
file (``--fcd-output``: XML, ``.xml.gz``, or SUMO's Parquet/CSV tabular output) and replays
it step by step to the same :class:`~sumo_drvpw.sim.loop.Stepper` the live loop uses, with
a connection object that answers the getters from the file. So masses, vClasses, equations,
slopes, wind and outputs are exactly those of ``run``; only what FCD lacks differs:

- speeds are as precise as the file (XML: ``--precision``, default 2 decimals; Parquet:
  float32); run SUMO with ``--precision 6`` for energies equal to the live run's;
- acceleration is (v_t − v_t−1)/Δt from the file's speeds (SUMO's own definition), or the
  file's ``acceleration`` column with ``sumo.acceleration = "getter"`` (needs
  ``--fcd-output.acceleration``);
- lane and position are read for every vehicle-step (no tracking);
- vTypes' masses and vClasses come from the scenario's route/additional files (``--vtypes``
  or ``[sumo]`` of the scenario; the ``fcd`` command takes those an XML FCD's header names,
  :func:`~sumo_drvpw.sim.fcd_read.recorded_inputs`); without them every vType is a
  ``passenger`` car with the class's default mass (listed in ``summary.json`` ``assumptions``);
- persons (``<person>``; in SUMO's tabular FCD rows without a lane) are not vehicles: they
  are counted in ``skipped`` as the live loop counts them, and a person whose x, y and
  speed equal a vehicle's rides in it, adding its vType's mass (route files; else SUMO's
  70 kg) as in the live loop (``summary.json`` ``source.riding_person_rows``);
- a parked vehicle (SUMO writes it with its lane, at speed 0, at the parking space's x, y)
  is told from a standing one by its x, y beside the lane (:class:`ParkedTest`) and, as in
  the live loop, not booked (``summary.json`` ``source.parked_rows``) but for the row it
  parks in, where SUMO moved it into its stop (booked driven, as live); FCD without x, y
  (``--fcd-output.attributes`` without them) tells it only at a parking stop the route
  files declare (:mod:`sumo_drvpw.sim.fcd_stops`; else booked standing, warned of);
  ``.geo``/``.utm`` x, y are brought back into the network's (:mod:`sumo_drvpw.sim.fcd_geo`);
  one whose parking is over but whose way out is blocked idles in its space
  and is booked standing there, as live (:mod:`sumo_drvpw.sim.fcd_idle`: told by the FCD's
  blinker bits, else by its declared stop's planned end; ``source.idling_rows``);
- vehicles are switched off at long planned stops and by start-stop systems as in the live
  run (:mod:`sumo_drvpw.sim.shutoff`): the vTypes' shut-off params from the route files,
  the stops from the route files' ``<stop>`` elements matched to where each vehicle stands
  (:mod:`sumo_drvpw.sim.fcd_stops`; stops a run added are booked standing, and counted in
  ``summary.json`` ``shut_off_at_long_stops.replay``);
- a vehicle row on a lane the network lacks is not booked (as the live loop books no
  vehicle without a lane); ``summary.json`` ``warnings`` counts them, and FCD none of
  whose vehicle rows is on a lane of the network is refused (:func:`~sumo_drvpw.sim.fcd_warn.lane_warnings`).

Bounded memory (#14): the file is read in blocks of ``chunk_rows`` rows
(:mod:`sumo_drvpw.sim.fcd_read`: XML iterparse, Parquet record batches, CSV chunks) and
replayed timestep by timestep (:class:`FcdStream`; a timestep cut by a block boundary is
joined first), so memory holds one block plus the running vehicles whatever the file's
length; the ledger writes finished vehicles out (:mod:`sumo_drvpw.sim.spill`). A vehicle
arrives the step after a timestep without it (SUMO's FCD does not tell an arrival from a
teleport: a vehicle back after a gap is put back there, as a teleport's end, and books on
from its next row; one whose rows end while it stands, or off its route's last edge — a moving
car's collision —, is held in memory for :data:`TELEPORT_HOLD_S` (:func:`~sumo_drvpw.sim.teleport.
may_return`), so a flush of finished vehicles does not split it — one back later books on in a
second row). ``chunk_rows=None`` reads the whole file first
(:class:`FcdReplay`: the reference the streamed replay equals exactly on gap-free FCD).
The rows must be in time order (SUMO writes them so). Split by vehicle on Dask:
:mod:`sumo_drvpw.sim.fcd_dask`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sumo_drvpw.errors import UserError
from sumo_drvpw.sim.dynamics import accel_bounds
from sumo_drvpw.sim.fcd_begin import begin_frame
from sumo_drvpw.sim.fcd_conn import ParkedTest, bus_stops, calibrators
from sumo_drvpw.sim.fcd_geo import NetCoordinates, recorded_coordinates
from sumo_drvpw.sim.fcd_idle import Idling, untold_warning
from sumo_drvpw.sim.fcd_method import recorded_method
from sumo_drvpw.sim.fcd_warn import (KineticGain, lane_warnings, missed_count, missing_input_warnings, no_angle_warning,
                                     partial_warnings, sparse_rows, sparse_warning, unplaced_person_warning,
                                     unplaced_vehicle_warning, unseen_vehicles)
from sumo_drvpw.sim.fcd_read import (CHUNK_ROWS, FCD_COLUMNS, fcd_parts,  # noqa: F401
                                     iter_fcd_blocks, read_fcd)
from sumo_drvpw.sim.fcd_replay import FcdReplay, FcdStream, timesteps
from sumo_drvpw.sim.fcd_stops import StopTracker, read_declared_stops
from sumo_drvpw.sim.teleport import may_return
from sumo_drvpw.sim.vtype_energy import battery_switch, replay_emission_classes
from sumo_drvpw.sim.vtypes import sumo_type_mass

#: how long [s] a vehicle whose rows end while it stands (or off its route's last edge: may_return) stays
#: in memory, in case it comes back from a teleport (SUMO teleports a car waiting in a jam or
#: colliding, writes no rows while it moves over the edges it skips at their speed limits —
#: seconds to minutes — and puts it back); one back later books on in a second row
TELEPORT_HOLD_S = 900.0


def fcd_scenario(net=None, scenario=None, equations=None, vtype_files=None, fcd_file=None,
                 **overrides):
    """The scenario an FCD replay books with: the scenario file's (or defaults around
    ``net``), equations and vType files replaced when given, positions read every step,
    the whole recording replayed unless ``end`` is given (:func:`replay_fcd`).
    Without a scenario, the network and vType files not given are those of the run that
    recorded ``fcd_file`` (:func:`~sumo_drvpw.sim.fcd_read.run_inputs`), where found."""
    import dataclasses

    from sumo_drvpw.sim.fcd_read import run_inputs
    from sumo_drvpw.sim.scenario import load_scenario

    if scenario is None and fcd_file is not None and (net is None or vtype_files is None):
        rec = run_inputs(fcd_file) or {}
        net = net if net is not None else rec.get("net")
        vtype_files = vtype_files if vtype_files is not None else (rec.get("files") or None)
    if scenario is None and net is None:
        raise UserError("FCD: give the network the FCD was recorded on, or a scenario")
    if net is not None and not Path(net).is_file():  # (before the scenario made of it names it)
        raise UserError(f"SUMO network {'is a folder, not a file' if Path(net).is_dir() else 'not found'}: {Path(net).resolve()}")
    if equations is not None:
        overrides["equations"] = list(equations)
    if scenario is not None:
        sc = load_scenario(scenario, **overrides)
    else:
        if "equations" not in overrides:
            raise UserError("FCD: give the equations, or a scenario that names them")
        sc = load_scenario(doc={"sumo": {"net": str(net)}}, **overrides)  # equations: the run's own
    changes = {"positions": "getter"}
    if net is not None:
        changes["net_file"] = Path(net).resolve()
    if vtype_files:
        files = [Path(f).resolve() for f in vtype_files]
        for f in files:
            if not f.is_file():
                raise UserError(f"vType file {'is a folder (give its route or additional files)' if f.is_dir() else 'not found'}: {f}")
        changes["route_files"] = files
    return dataclasses.replace(sc, **changes)


def process_fcd(fcd_file, net=None, scenario=None, out_dir=None, equations=None,
                vtype_files=None, begin_s=None, keep_vehicles: bool = False,
                flush_vehicles: int | None = None, chunk_rows: int | None = CHUNK_ROWS,
                **overrides):
    """Book an FCD file as ``run`` books a live simulation; returns the RunResult and
    writes the outputs into ``out_dir`` when given.

    Parameters
    ----------
    fcd_file : SUMO FCD output (XML, .xml.gz, .parquet, .csv), or partitioned Parquet FCD
        (a folder or a glob pattern of parts)
    net : the network the FCD was recorded on (default: the scenario's, else the one the
        FCD's header or the config that writes it names, :func:`fcd_scenario`)
    scenario : optional scenario TOML (options, vTypes, equations)
    equations : equations instead of the scenario's (names, paths, Equation objects)
    vtype_files : route/additional files with the vTypes (default: the scenario's, else
        those the FCD's header or config names)
    begin_s : ignore timesteps before this simulation time [s]
    keep_vehicles, flush_vehicles : as for :func:`sumo_drvpw.sim.run.run_scenario` (a
        vehicle leaves memory the step after its last row in the file)
    chunk_rows : rows read at a time (the file streamed in bounded memory); None reads
        the whole file first (:func:`read_fcd`, :class:`FcdReplay`: the reference path)
    overrides : scenario values to replace (``sumo_drvpw.sim.scenario.OVERRIDES``)

    Streamed, ``summary["source"]["rows"]`` counts the rows of the replayed timesteps (in
    memory: every row from ``begin_s`` on). For many vehicles on several processes or
    machines see :func:`sumo_drvpw.sim.fcd_dask.process_fcd_dask`.
    """
    sc = fcd_scenario(net, scenario, equations, vtype_files, fcd_file, **overrides)
    return replay_fcd(sc, fcd_file, out_dir, begin_s=begin_s, keep_vehicles=keep_vehicles,
                      flush_vehicles=flush_vehicles, chunk_rows=chunk_rows,
                      inputs=missing_input_warnings(fcd_file, scenario, vtype_files))


def replay_fcd(sc, fcd_file, out_dir=None, begin_s=None, keep_vehicles: bool = False,
               flush_vehicles: int | None = None, chunk_rows: int | None = CHUNK_ROWS,
               keep=None, publish: bool = True, count_persons: bool = True, inputs=([], [])):
    """:func:`process_fcd` with a prepared scenario (:func:`fcd_scenario`). ``inputs``:
    the warnings and the files of :func:`~sumo_drvpw.sim.fcd_warn.missing_input_warnings`
    (summary.json ``warnings``, ``source.inputs_not_found``). ``keep``:
    optional function vehicle ids → boolean mask of the vehicles to book (a Dask task's
    share; every person's rows are kept, to be matched to the vehicle it rides);
    ``publish``: write the outputs into ``out_dir`` (else only the spill parts of the
    vehicles are left there, for :mod:`sumo_drvpw.sim.fcd_dask` to join);
    ``count_persons``: count the persons in ``summary.json`` ``skipped`` (one Dask task
    does)."""
    from sumo_drvpw.sim.accountant import Accountant
    from sumo_drvpw.sim.stepping import step_until
    from sumo_drvpw.sim.network import hidden_steps_slack, load_network
    from sumo_drvpw.sim.run import check_vtype_filter
    from sumo_drvpw.sim.spill import SPILL_DIR, discard_parts, write_published
    from sumo_drvpw.sim.sumo_start import scenario_option

    net = load_network(sc.net_file, sc.road_class, sc.slope_window, sc.slope_max)
    # the recording is replayed whole unless the run was given an end: the scenario's or its
    # config's is not the one the recording's run had (a rehearsal's FCD recorded to 3600 s
    # with `--end` was replayed to its config's 1200 s without a word); flows without an end
    # still end at the scenario's (its stops: read_declared_stops)
    cut = sc.end if sc.end_given else None
    # bus stops of the additional files, and of the files given for the vTypes (--vtypes)
    from sumo_drvpw.sim.fcd_read import header_options

    head = header_options(fcd_file)  # the recording's options (None: no SUMO header)
    # (x, y written as longitude, latitude or UTM: brought back into the network's)
    coords = NetCoordinates(recorded_coordinates(head), sc.net_file)
    parked = ParkedTest(net, bus_stops(list(dict.fromkeys([*sc.additional_files, *sc.route_files]))), coords)
    sc = recorded_device_options(sc, head)
    dt, dt_warning = row_interval(sc, fcd_file, head)
    method, method_note = recorded_method(sc, head, fcd_file, dt)  # (a header, the scenario, or the rows)
    net.jump_slack_m = hidden_steps_slack(recorded_step(head), dt)  # rows sparser than the step
    if chunk_rows is None:
        df = read_fcd(fcd_file)
        if {"x", "y"} <= set(df.columns):
            xy = {k: df[k].to_numpy() for k in ("x", "y", "lane", "pos")}
            coords.convert(xy, net)
            df["x"], df["y"] = xy["x"], xy["y"]
        df["off"], df["bay"] = parked.marks({k: df[k].to_numpy() for k in df.columns})
        df["lane_ok"] = parked.lane_ok({"lane": df["lane"].to_numpy()})
        if keep is not None and len(df):
            times = df.attrs["times"]
            df = df[keep(df["id"].to_numpy(object)) | df["person"].to_numpy(bool)].copy()
            df.attrs["times"] = times
        replay_info = {}
        if begin_s is not None:
            times = df.attrs["times"]
            replay_info["skipped"] = bool((times < begin_s - 1e-9).any())
            t_b, t_f = times[times < begin_s - 1e-9], times[times >= begin_s - 1e-9]
            df = df[df["time"] >= begin_s - 1e-9].copy() if not (len(t_b) and len(t_f)) else \
                begin_frame(df, float(t_b[-1]), float(t_f[0]))
            df.attrs["times"] = t_f
        replay = FcdReplay(df, dt=dt)
        if cut is not None:
            n = int(np.searchsorted(replay.times + replay.dt, cut + 1e-9, side="right"))
            replay.times, replay._rows = replay.times[:n], replay._rows[:n]
    else:
        replay_info = {}
        steps = timesteps(parked.mark(iter_fcd_blocks(fcd_file, chunk_rows)), begin_s, keep,
                          fcd_file, replay_info)
        replay = FcdStream(steps, dt=dt, end_s=cut, label=fcd_file)
    if keep is None and not (replay._ahead if chunk_rows is not None else len(replay.times)):
        # (SUMO writes every timestep; a Dask bucket may be empty)
        raise UserError(f"FCD file {fcd_file}: no timestep (in the time asked for): not SUMO's "
                        "FCD output (<timestep> elements, or rows with a time column)?")
    if out_dir is not None:
        Path(out_dir).mkdir(parents=True, exist_ok=True)
    replay.options = {"step-method.ballistic": str(method == "ballistic").lower()}
    # (not given: SUMO switched to ballistic where a vType of its own action step length ran)
    replay.asl_may_switch = (head.get("step-method.ballistic") if head is not None
                             else scenario_option(sc, "step-method.ballistic")) is None
    replay.recorded_step_s = recorded_step(head)  # (the radial drag of vtype_energy: per step of it)
    replay.calibrators = calibrators(list(dict.fromkeys([*sc.additional_files, *sc.route_files])))
    acc = Accountant(replay, scenario=sc,
                     trace_path=Path(out_dir) / "trace.parquet" if sc.trace and out_dir else None,
                     spill_dir=Path(out_dir) / SPILL_DIR if out_dir is not None else None,
                     keep_vehicles=keep_vehicles, flush_vehicles=flush_vehicles, net=net)
    if getattr(acc, "file_vtypes", None) is not None:  # a [vtypes.X] of no vType: refused as a run does
        from sumo_drvpw.sim.run import check_vtype_tables

        check_vtype_tables(sc, acc.file_vtypes)
    replay.type_mass.update({vt: sumo_type_mass(acc.file_vtypes, vt) for vt in acc.file_vtypes})  # (riders')
    replay.container_types = set(getattr(acc.file_vtypes, "container_types", ()))
    replay.type_accel = accel_bounds(acc.file_vtypes)  # (a placement: a speed gain beyond them)
    replay.type_asl = {vt: i.action_step_s for vt, i in acc.file_vtypes.items() if i.action_step_s is not None}
    # long planned stops and start-stop systems as in the live run (sim/shutoff.py): the
    # vTypes' shut-off params and the vehicles' stops from the route and additional files
    replay.type_params = {vt: i.shut_off for vt, i in acc.file_vtypes.items() if i.shut_off}
    # (a vType writing none runs on SUMO's Energy model where the battery device is on: as live)
    replay.type_eclass, replay.default_eclass = replay_emission_classes(acc.file_vtypes, battery_switch(sc))
    # SUMO loads the additional files first: a route (with its stops) defined there serves
    # the vehicles of the route files
    declared = read_declared_stops(list(dict.fromkeys([*sc.additional_files, *sc.route_files])), begin=sc.begin,
                                   end=sc.end, option=lambda key: scenario_option(sc, key) or (head or {}).get(key))
    replay.stops, replay.taxis = StopTracker(declared, net) if declared else None, declared.taxis
    acc.ledger.hold_steps, acc.ledger.may_return = int(np.ceil(TELEPORT_HOLD_S / replay.dt)), may_return(declared, net, acc.ledger)
    # a parked car idling in its space, its way out blocked, as the live run books it
    so = acc.stepper.shutoff
    replay.idling = Idling(replay.stops, so.limit_of if so is not None else lambda vt: np.inf,
                           replay.recorded_step_s or replay.dt)
    acc.stepper.replay_info = replay_info  # a --begin after the file's start: no cold starts then
    replay.count_persons = count_persons
    sparse, t0 = sparse_rows(head), replay.t  # rows written less often than the run stepped; its first row's time
    replay.kinetic = KineticGain() if sparse else None
    replay.unseen, unseen_why = unseen_vehicles(declared, head, begin_s, cut, keep) if sparse else ({}, "")
    try:
        info = step_until(replay, acc.stepper, end=None, progress=sc.progress and publish, period=sc.period,
                          period_from=sc.period_from)
        acc.interrupted = info["interrupted"]
        acc.fcd_lanes = (replay.unknown_rows, replay.lane_rows, replay.first_unknown)
        rows = replay.rows if chunk_rows is not None else len(df)
        extra = {"source": {"fcd": str(fcd_file), "rows": int(rows),
                            "timesteps": int(replay.k), "parked_rows": int(replay.parked_rows),
                            "idling_rows": int(replay.idle_rows), "untold_parked_rows": int(replay.idling.untold_rows),
                            "untold_parked_vehicles": len(replay.idling.untold_ids),
                            "riding_person_rows": int(replay.rider_rows), "unplaced_vehicle_rows": int(replay.blind_rows),
                            "unplaced_person_rows": int(replay.unplaced_person_rows),
                            "declared_parked_rows": int(replay.stops.inferred_rows if replay.stops else 0),
                            "inputs_not_found": list(inputs[1])}}
        replay.missed = missed_count(replay.unseen, unseen_why, t0, replay.t - (sparse or [0])[0], len(declared.random_flows))
        if sc.trace and out_dir:
            extra["files"] = {"trace": "trace.parquet"}
        if not publish:
            acc.close_trace()
            return acc, extra
        warn = (list(inputs[0]) + lane_warnings(fcd_file, sc.net_file, *acc.fcd_lanes) + dt_warning
                + [method_note] * bool(method_note) + partial_warnings(fcd_file, head)
                + sparse_warning(fcd_file, sparse, replay.kinetic.doubled_loss() if sparse else None, replay.missed))
        if replay.no_angle and acc.eqset.uses_yaw:
            warn.append(no_angle_warning(fcd_file))
        if replay.unplaced_person_rows and sc.transportable_mass:
            warn.append(unplaced_person_warning(fcd_file, replay.unplaced_person_rows))
        if replay.idling.untold_rows:
            warn.append(untold_warning(fcd_file, replay.idling.untold_rows, len(replay.idling.untold_ids)))
        if coords.lost:
            warn.append(f"FCD file {fcd_file}: {coords.lost}: its rows are read as without x, y")
        if replay.blind_rows:
            warn.append(unplaced_vehicle_warning(fcd_file, replay.blind_rows, extra["source"]["declared_parked_rows"],
                                                 replay.stops is not None))
        if warn:
            extra["warnings"] = warn
        result = acc.result(extra)
        check_vtype_filter(sc, acc.ledger)
        if out_dir is not None:
            write_published(result, out_dir)
    finally:
        acc.close_trace()
        if out_dir is not None and publish:
            discard_parts(acc.ledger)
    return result


#: SUMO options of the recording run that decide which vTypes SUMO ran on its Energy model
#: (sim/vtype_energy.py): taken from an XML FCD's header when the scenario gives none
RECORDED_DEVICE_OPTIONS = ("device.battery.probability", "device.battery.track-fuel")


def recorded_device_options(sc, head: dict | None):
    """``sc`` with the battery-device options of the run that recorded the FCD (its header
    ``head``) added to its SUMO options where the scenario sets none: with SUMO's option
    device.battery.probability 1 a vType without emissionClass runs on SUMO's Energy model,
    so the replay's ``vtype_energy`` books it as the live run does."""
    import dataclasses

    from sumo_drvpw.sim.sumo_start import scenario_option

    add = [x for k in RECORDED_DEVICE_OPTIONS if head and head.get(k) is not None
           and scenario_option(sc, k) is None for x in (f"--{k}", head[k])]
    return dataclasses.replace(sc, sumo_args=[*sc.sumo_args, *add]) if add else sc


def recorded_step(head: dict | None) -> float | None:
    """The step length [s] of the run that wrote an XML FCD (its header; SUMO's default
    1 s when not named), None without a header."""
    try:
        return None if head is None else float(head.get("step-length", 1.0))
    except ValueError:
        return None


def row_interval(sc, fcd_file, head: dict | None) -> tuple[float | None, list[str]]:
    """The time between an FCD file's timesteps [s] — the Δt each row is booked over (SUMO
    moved the car v·Δt in it) — and a warning when the scenario says otherwise.

    An XML FCD's header names the recording's step length and ``device.fcd.period`` when
    they differ from SUMO's defaults (1 s, every step): the rows are max(step, period)
    apart, whatever the scenario's or config's ``step_length`` (a run given another step
    length on the command line, or FCD written every few steps). Without a header, the
    scenario's step length; without one either, None (the file's first two timesteps).
    ``head``: the file's header options (:func:`sumo_drvpw.sim.fcd_method.stated_method`)."""
    if head is None:
        return sc.step_length, []
    try:
        step = float(head.get("step-length", 1.0))
        period = float(head.get("device.fcd.period", 0.0) or 0.0)
    except ValueError:
        return sc.step_length, []
    dt = max(step, period) if step > 0 else sc.step_length
    if sc.step_length is None or dt is None or abs(dt - sc.step_length) <= 1e-9:
        return dt, []  # (rows sparser than the steps: fcd_warn.sparse_warning, after the replay)
    why = f"step-length {step:g} s" + (f", device.fcd.period {period:g} s" if period > step else "")
    return dt, [f"FCD {Path(fcd_file).name}: its rows are {dt:g} s apart (its header: {why}); each is booked "
                f"over {dt:g} s, not the scenario's step length of {sc.step_length:g} s"]
