"""`fcd` on a Dask cluster (#14): the vehicles split into buckets, one task per bucket.

A vehicle's energies depend on its own rows only, so the work splits by vehicle exactly:
vehicle ids are hashed (:func:`bucket_of`, the same in every process) into ``buckets``
buckets; each task streams the whole FCD (:mod:`sumo_drvpw.sim.fcd_read`, bounded memory),
books only its bucket's vehicles through the same replay and ledger as the local engine
(every timestep is stepped, so steps, edgeData intervals and end time agree), writes its
vehicles' rows as Parquet parts into the output folder and returns its ledger's sums. The
driver adds them up (:func:`merge_ledgers`: edge, interval, class and chain totals summed,
counters summed) and writes what ``fcd`` writes; ``vehicles.parquet`` joins the tasks'
parts (rows grouped by bucket). Results equal the local engine's up to the order of
floating-point additions (tests: 1e-9 relative).

Each task reads the whole file: the cluster's reading work is ``buckets`` × the file, the
booking work is split. Parts and outputs are written into ``out_dir``: on a cluster of
other machines it must be on a filesystem the workers share. Not on Dask: a per
vehicle-step trace (``outputs.trace``). ``vehicles_in_memory_peak`` is the most one task
held at once.
"""

from __future__ import annotations

import copy
import os
import shutil
from functools import partial
from pathlib import Path

import numpy as np
import pandas as pd

from sumo_drvpw.errors import UserError
from sumo_drvpw.sim.fcd_read import CHUNK_ROWS

#: folder of the tasks' parts inside the output folder (removed after writing)
BUCKET_DIR = ".drvpw-fcd-buckets"


def bucket_of(ids, buckets: int) -> np.ndarray:
    """Bucket number of each vehicle id: pandas' fixed-key hash of the string, modulo
    ``buckets`` (the same on every machine and in every process)."""
    ids = np.asarray(ids, dtype=object)  # the readers' ids are str already
    codes, uniq = pd.factorize(ids)  # a vehicle has many rows: hash each id once
    h = pd.util.hash_array(np.asarray([str(u) for u in uniq], dtype=object), categorize=False)
    return (h % np.uint64(buckets)).astype(np.int64)[codes]


def _in_bucket(ids, b: int, buckets: int) -> np.ndarray:
    return bucket_of(ids, buckets) == b


def bucket_task(sc, fcd_file: str, part_dir: str, b: int, buckets: int, begin_s=None,
                chunk_rows: int = CHUNK_ROWS, flush_vehicles: int | None = None) -> dict:
    """Book bucket ``b`` of ``buckets`` of an FCD (runs on a worker): every vehicle ends
    up flushed into Parquet parts under ``part_dir``; returns the ledger (without its
    spill), the parts and what the summary needs from the replay."""
    from sumo_drvpw.sim.fcd import replay_fcd

    acc, extra = replay_fcd(sc, fcd_file, part_dir, begin_s=begin_s,
                            flush_vehicles=flush_vehicles, chunk_rows=chunk_rows,
                            keep=partial(_in_bucket, b=b, buckets=buckets), publish=False,
                            count_persons=b == 0)
    led = acc.ledger
    if led.n_veh:  # the vehicles running at the end go out too: the ledger keeps sums only
        led.retire(np.arange(led.n_veh), at_end=True)
        led.hold_steps = 0  # the replay is over: none comes back
        acc.stepper.flush()
    spill = led.spill
    if spill._finalizer is not None:
        spill._finalizer.detach()  # the driver joins the parts, then removes them
    parts = {"parts": [str(p) for p in spill.parts], "chain_parts": [str(p) for p in spill.chain_parts],
             "chain_columns": spill.chain_columns, "rows": spill.rows}
    led.spill = None
    r = acc.resolver
    return {"ledger": led, "spill": parts, "extra": extra, "begin": acc.begin,
            "end": acc.stepper.now(), "dt": acc.stepper.dt, "missed_steps": acc.stepper.missed_steps,
            "interrupted": acc.interrupted, "skipped": r.skipped, "excluded": r.excluded,
            "assumptions": r.assumptions, "sumo_masses": r.sumo_masses, "seen_vtypes": [*r.cache, *r.seen],
            "carriers": r.carriers, "powertrains": r.powertrains, "booked_as": r.booked_as,
            "also_booked": r.also_booked, "mass_far": r.mass_far, "fixed_far": r.fixed_far,
            "untold_copies": r.untold_copies, "told_copies": r.told_copies,
            "lanes": acc.fcd_lanes, "no_angle": bool(acc.conn.no_angle and acc.eqset.uses_yaw),
            "stops_read": acc.conn.stops is not None, "missed": getattr(acc.conn, "missed", None),
            "kinetic": (None if acc.conn.kinetic is None  # (rows sparser than the steps: fcd_warn)
                        else (acc.conn.kinetic.gain.tolist(), acc.conn.kinetic.n.tolist())),
            "shutoff": acc.stepper.shutoff.summary() if acc.stepper.shutoff is not None else None}


#: keys of the shut-off summary read from the files, the same in every bucket (not added up)
_FROM_FILES = {"declared_stops_on_unknown_stopping_places"}


def merge_shutoff(summaries: list) -> dict | None:
    """The buckets' shut-off summaries (sim/shutoff.py ``summary``) as one: counts and
    seconds added up (each bucket switched its own vehicles off), rules and what the files
    say taken once."""
    done = [s for s in summaries if s]
    if not done:
        return None
    out = copy.deepcopy(done[0])

    def add(a: dict, b: dict) -> None:
        for k, v in b.items():
            if isinstance(v, dict):
                add(a.setdefault(k, {}), v)
            elif isinstance(v, (int, float)) and not isinstance(v, bool) and k not in _FROM_FILES:
                a[k] = a.get(k, 0) + v

    for s in done[1:]:
        add(out, s)
    return out


def merge_ledgers(ledgers: list):
    """One ledger holding the sums of several ledgers of the same run that booked disjoint
    vehicles, all flushed (no vehicle in memory): the first one, added to in place."""
    out = ledgers[0]
    for led in ledgers[1:]:
        if led.steps != out.steps or len(led.snapshots) != len(out.snapshots):
            raise RuntimeError("fcd buckets stepped different timesteps")
        for name in ("_edge_closed", "_edge_dist_closed", "_edge_time_closed",
                     "_edge_dist_eq_closed", "_edge_time_eq_closed", "edge_count", "edge_entered", "out_of_range",
                     "lane_clipped", "edge_teleports", "edge_tele"):
            setattr(out, name, getattr(out, name) + getattr(led, name))
        for name in ("samples", "corrected", "clipped", "position_reads", "position_mismatches",
                     "flushed_vehicles", "flushed_kept", "load_samples", "teleports", "hard_brakes"):
            setattr(out, name, getattr(out, name) + getattr(led, name))
        out.load_max_kg = max(out.load_max_kg, led.load_max_kg)
        out.hard_brake_max_mps2 = max(out.hard_brake_max_mps2, led.hard_brake_max_mps2)
        out.dynamics.merge(led.dynamics)
        for name in ("chainless", "chainless_vtypes"):  # (vClass or vType → vehicles)
            for k, n in getattr(led, name).items():
                getattr(out, name)[k] = getattr(out, name).get(k, 0) + n
        for c, types in led.class_vtypes.items():
            out.class_vtypes.setdefault(c, {}).update(types)
        out.snapshots = [(s[0],) + tuple(x + y for x, y in zip(s[1:], o[1:]))
                         for s, o in zip(out.snapshots, led.snapshots)]
        out.flushed_types |= led.flushed_types
        out.peak_held = max(out.peak_held, led.peak_held)
        out.class_list += [c for c in led.class_list if c not in out.class_list]
        if out.chain is not None:
            a, b = out.chain, led.chain
            a._edge = a._edge + b._edge
            a.edge_dist = a.edge_dist + b.edge_dist
            a.booked_any = a.booked_any | b.booked_any
            a.cold_starts += b.cold_starts
            a.cold_starts_expected += b.cold_starts_expected
            if a.charges is None:  # (a bucket's plug-ins driving at --begin make one: sim/chain_charge.book_departures)
                a.charges = b.charges
            elif b.charges is not None:  # plug-ins departing with a declared charge, or driving at --begin
                a.charges.departed, a.charges.charge_wh = a.charges.departed + b.charges.departed, a.charges.charge_wh + b.charges.charge_wh
                a.charges.at_begin += b.charges.at_begin
            a.snapshots = [(s[0], s[1] + o[1]) for s, o in zip(a.snapshots, b.snapshots)]
            for c, (q, m) in b.flushed_class.items():
                acc = a.flushed_class.setdefault(c, [np.zeros((a.E, a.Q)), np.zeros(a.A)])
                acc[0] = acc[0] + q
                acc[1] += m
            a.assumed_zero |= b.assumed_zero
            a.motor_invalid = a.motor_invalid + b.motor_invalid  # per equation: MMPEVEM nan steps
            a.over_engine = a.over_engine + b.over_engine        # demand beyond a rated output
    out._edge_cache = None
    return out


def process_fcd_dask(fcd_file, out_dir, net=None, scenario=None, equations=None,
                     vtype_files=None, begin_s=None, buckets: int | None = None,
                     scheduler: str | None = None, workers: int | None = None,
                     chunk_rows: int = CHUNK_ROWS, flush_vehicles: int | None = None,
                     **overrides):
    """:func:`sumo_drvpw.sim.fcd.process_fcd` on a Dask cluster: ``buckets`` tasks (default:
    the cluster's worker count) of one vehicle bucket each; ``scheduler``: the address of an
    existing cluster, else a local cluster of ``workers`` processes. Writes the outputs into
    ``out_dir`` (required: the workers write their parts there) and returns the RunResult."""
    from sumo_drvpw.fit.engine import dask_client, guarded, unguarded
    from sumo_drvpw.sim.accountant import Accountant
    from sumo_drvpw.sim.fcd import fcd_scenario, recorded_device_options, recorded_step
    from sumo_drvpw.sim.fcd_replay import FcdStream
    from sumo_drvpw.sim.fcd_idle import untold_warning
    from sumo_drvpw.sim.fcd_warn import (KineticGain, lane_warnings, missing_input_warnings, no_angle_warning,
                                         merge_missed, partial_warnings, sparse_rows,
                                         sparse_warning, unplaced_person_warning,
                                         unplaced_vehicle_warning)
    from sumo_drvpw.sim.fcd_read import fcd_parts, header_options
    from sumo_drvpw.sim.run import check_vtype_filter
    from sumo_drvpw.sim.spill import VehicleSpill, write_published

    sc = fcd_scenario(net, scenario, equations, vtype_files, fcd_file, **overrides)
    inputs = missing_input_warnings(fcd_file, scenario, vtype_files)
    if sc.trace:
        raise UserError("FCD on Dask: no per vehicle-step trace (outputs.trace); replay "
                        "locally for a trace")
    if buckets is not None and buckets < 1:
        raise UserError(f"FCD on Dask: buckets must be ≥ 1, got {buckets}")
    spec = str(fcd_file)
    if not fcd_parts(spec) and not Path(spec).is_file():
        raise UserError(f"FCD file not found: {spec}")
    spec = os.path.abspath(spec)  # a worker's working folder is not ours
    head = header_options(spec)
    sc = recorded_device_options(sc, head)  # as each bucket's replay takes them
    out = Path(out_dir).resolve()
    root = out / BUCKET_DIR
    root.mkdir(parents=True, exist_ok=True)
    try:
        with dask_client(scheduler, workers) as client:
            k = buckets or max(1, len(client.scheduler_info().get("workers", {})))
            futs = [client.submit(guarded, bucket_task, sc, spec, str(root / f"b{b:04d}"), b, k, begin_s,
                                  chunk_rows, flush_vehicles, pure=False, key=f"fcd-bucket-{b}-of-{k}")
                    for b in range(k)]
            done, led = [], None
            for f in futs:  # in bucket order; a failed task raises its error here
                d = unguarded(f.result())  # a bad input: its one-line UserError
                f.release()
                one = d.pop("ledger")  # added up at once: one ledger's sums held, not K
                led = one if led is None else merge_ledgers([led, one])
                done.append(d)
        firsts = [d["lanes"][2] for d in done if d["lanes"][2] is not None]
        warn = inputs[0] + lane_warnings(spec, sc.net_file, sum(d["lanes"][0] for d in done),
                                         sum(d["lanes"][1] for d in done),
                                         min(firsts, key=lambda x: x[1]) if firsts else None)
        warn += partial_warnings(spec, head)
        gains = [d["kinetic"] for d in done if d.get("kinetic") is not None]
        if gains:  # each vehicle in one bucket: the gains and intervals add up
            kin = KineticGain()
            kin.gain, kin.n = (np.sum([np.asarray(g[i]) for g in gains], axis=0) for i in (0, 1))
            missed = [d["missed"] for d in done if d.get("missed") is not None]  # (vehicles in no row)
            warn += sparse_warning(spec, sparse_rows(head), kin.doubled_loss(),
                                   merge_missed(missed) if missed else None)
        if any(d["no_angle"] for d in done):
            warn.append(no_angle_warning(spec))
        unplaced = max(d["extra"]["source"].get("unplaced_person_rows", 0) for d in done)
        if unplaced and sc.transportable_mass:  # (every bucket reads every person's rows)
            warn.append(unplaced_person_warning(spec, unplaced))
        untold = [sum(d["extra"]["source"][k] for d in done) for k in ("untold_parked_rows", "untold_parked_vehicles")]
        if untold[0]:  # (each vehicle in one bucket: their counts add up)
            warn.append(untold_warning(spec, *untold))
        blind = [sum(d["extra"]["source"][k] for d in done) for k in ("unplaced_vehicle_rows", "declared_parked_rows")]
        if blind[0]:
            warn.append(unplaced_vehicle_warning(spec, *blind, any(d["stops_read"] for d in done)))
        # the driver's own accountant (no rows) carries the scenario, network and resolver
        first = done[0]
        replay = FcdStream(iter(()), dt=first["dt"], label=spec)
        replay.recorded_step_s = recorded_step(head)  # as the buckets' (vtype_energy's radial drag)
        acc = Accountant(replay, scenario=sc, keep_vehicles=True)
        spill = VehicleSpill(acc.names, [e.predicts for e in acc.equations], None)
        for d in done:
            spill.parts += [Path(p) for p in d["spill"]["parts"]]
            spill.chain_parts += [Path(p) for p in d["spill"]["chain_parts"]]
            spill.chain_columns = spill.chain_columns or d["spill"]["chain_columns"]
            spill.rows += d["spill"]["rows"]
        led.spill = spill
        acc.ledger = acc.stepper.ledger = led
        acc.begin, replay.t = first["begin"], first["end"]
        acc.stepper.missed_steps = first["missed_steps"]
        acc.interrupted = any(d["interrupted"] for d in done)
        r = acc.resolver
        r.excluded = sum(d["excluded"] for d in done)
        for d in done:
            r.assumptions.update(d["assumptions"])
            r.sumo_masses.update(d["sumo_masses"])
            for key in ("carriers", "powertrains", "booked_as", "also_booked", "mass_far", "fixed_far",
                        "untold_copies", "told_copies"):  # what each bucket's vTypes were booked as
                getattr(r, key).update(d[key])
            r.seen.update(d["seen_vtypes"])  # the vTypes the buckets resolved
            for key, counts in d["skipped"].items():
                for name, n in counts.items():
                    r.skipped[key][name] = r.skipped[key].get(name, 0) + n
        extra = dict(first["extra"])
        extra["source"] = dict(extra["source"], rows=sum(d["extra"]["source"]["rows"] for d in done),
                               parked_rows=sum(d["extra"]["source"]["parked_rows"] for d in done),
                               idling_rows=sum(d["extra"]["source"]["idling_rows"] for d in done),
                               untold_parked_rows=untold[0], untold_parked_vehicles=untold[1],
                               unplaced_vehicle_rows=blind[0], declared_parked_rows=blind[1],
                               inputs_not_found=inputs[1],
                               riding_person_rows=sum(d["extra"]["source"]["riding_person_rows"]
                                                      for d in done),
                               engine="dask", buckets=k)
        if warn:
            extra["warnings"] = warn
        result = acc.result(extra)
        # the driver's accountant read no rows: the switch-offs are the buckets'
        result.summary["shut_off_at_long_stops"] = merge_shutoff([d["shutoff"] for d in done])
        check_vtype_filter(sc, led)
        write_published(result, out)
    finally:
        shutil.rmtree(root, ignore_errors=True)
    return result
