"""ASAM MDF measurement files (``.mf4``, ``.mdf``, ``.dat``) through the ``columns`` mapping.

CAN and data loggers (Vector, ETAS, CSS Electronics' CANedge, dSPACE, …) write ASAM MDF;
``sumo-drvpw import columns LOGS --columns mapping.toml`` reads them with the same mapping
TOML as CSV files (:mod:`sumo_drvpw.data.adapters.columns`), a source label naming a
channel instead of a column. What differs:

* **Time** is the file's own time base: the speed channel's time stamps (seconds since the
  measurement's start). ``time_s`` needs no mapping, and one is refused.
* **One row per speed sample.** Every other mapped channel is put onto the speed channel's
  time stamps (:mod:`sumo_drvpw.data.adapters.align`): a measured value linearly in time,
  or, logged at least twice as fast as the speed, as its mean over each speed sample's
  interval (the charge of each interval, not the current of one instant); a state (integer
  or boolean without a physical unit: a gear, a flag) held from its last sample; across
  gaps up to :data:`~sumo_drvpw.data.adapters.align.ALIGN_MAX_GAP_INTERVALS` × the
  channel's median sampling interval, NaN beyond (the logger paused the channel) and
  outside its time span.
* **Units** come from the file when the mapping gives none (the channel's unit, e.g.
  ``km/h``, ``degC``); a unit in the mapping overrides it.
* **Only mapped channels** are read (a bus log holds hundreds); ``keep_unmapped`` has no
  effect on MDF files. Each file is one trip, named after the file; with ``[options]
  mdf_trips = "folder"`` the files of each folder are one trip, named after the folder,
  joined in time (a logger that splits a session into files of some minutes, as a CANedge
  writes ``LOG/<device>/<session>/00000001.MF4, …``; asammdf's concatenation keeps each
  file's time stamps from the session's start).
* **Raw bus logs** (CAN frames, as a CANedge writes them) are decoded first with the DBC
  files of ``[options] dbc = ["powertrain.dbc", …]`` (paths relative to the mapping file;
  every CAN bus channel). A signal is then named by its DBC name (``Speed``) or, where two
  messages carry the same name, ``MESSAGE.Signal``. Diagnostic responses longer than a
  frame (a BEV's battery data as UDS responses over ISO-TP) are reassembled first
  (:mod:`~sumo_drvpw.data.adapters.isotp`; ``[options] isotp_layout``).
* A channel name found in several channel groups is named as ``name@GROUP`` (the group's
  number, as the error lists them).
* Samples the file marks invalid (MDF 4 invalidation bits) are left out by asammdf, as a
  gap; a channel's ``valid = "FLAG"`` (a CAN signal's validity bit, e.g. a GNSS altitude's
  ``AltitudeValid``) reads its samples where the flag is 0 as missing, before they are put
  onto the speed's samples; an integer channel whose value table turns it into texts (a
  gear ``P``/``D``) is read as its raw numbers (noted).
* ``.mf4`` and ``.mdf`` files are MDF; any other file (``.dat`` is also a text suffix) is
  MDF when its first bytes are MDF's identification (:func:`is_mdf`).

Reading MDF needs the optional package asammdf (``pip install 'sumo-drvpw[mdf]'``).
"""

from __future__ import annotations

import difflib
from pathlib import Path

import numpy as np
import pandas as pd

from sumo_drvpw.errors import UserError
from sumo_drvpw.data.adapters._common import clean_time_and_speed, lookup_unit, new_report
from sumo_drvpw.data.adapters.align import POWER_FACTORS, held, how, keep_power, onto

SUFFIXES = (".mf4", ".mdf", ".dat")
INSTALL = "pip install 'sumo-drvpw[mdf]'"


#: the identification block every MDF 3/4 file begins with (finalised, and as a logger leaves
#: it unfinalised)
MAGIC = (b"MDF     ", b"UnFinMF ")


def is_mdf(path) -> bool:
    """Whether a file is read as ASAM MDF: by its suffix ``.mf4``/``.mdf``; any other file
    (``.dat`` is also a text suffix) by its first bytes, MDF's identification."""
    p = Path(path)
    if p.suffix.lower() in (".mf4", ".mdf"):
        return True
    try:
        with open(p, "rb") as f:
            return f.read(8) in MAGIC
    except OSError:  # unreadable: the reader of its kind says why
        return False


def _open(path: Path, m: dict, parts: list[Path] | None = None, notes: list | None = None):
    """The file as an asammdf ``MDF`` (its CAN frames decoded with the mapping's DBC files,
    multi-frame diagnostic responses reassembled first: :mod:`~sumo_drvpw.data.adapters.isotp`);
    ``parts``: the files of one logging session (``path`` their folder), joined in time;
    ``notes``: the import notes, which it adds to."""
    notes = [] if notes is None else notes
    try:
        from asammdf import MDF
    except ImportError:
        raise UserError(f"{path}: reading ASAM MDF files needs the package asammdf: {INSTALL}") from None
    try:
        mdf = MDF(str(path)) if parts is None else MDF.concatenate([str(p) for p in parts])
    except Exception as e:  # asammdf raises many kinds on a file that is not MDF
        first = (str(e).splitlines() or [type(e).__name__])[0]
        what = ("cannot be read as ASAM MDF" if parts is None else
                f"its {len(parts)} MDF files cannot be joined into one trip (options.mdf_trips = "
                "\"folder\": the split files of one logging session)")
        raise UserError(f"{path}: {what}: {first}") from None
    if not m.get("dbc"):
        return mdf
    from sumo_drvpw.data.adapters import isotp

    try:
        dbs, tp = isotp.split_databases(mdf, m["dbc"])
        decoded = mdf.extract_bus_logging({"CAN": [(db, 0) for db in dbs]})
        if tp:
            counts = isotp.decode_into(decoded, mdf, tp, m["isotp_layout"])
            notes.append("ISO-TP responses reassembled (options.isotp_layout = "
                         f"{m['isotp_layout']!r}): "
                         + ", ".join(f"{k} {a}" + (f" ({b} incomplete, left out: a first frame without its "
                                                   "consecutive frames — no flow control, or a frame lost)" if b else "")
                                     for k, (a, b) in counts.items()))
    except Exception as e:
        first = (str(e).splitlines() or [type(e).__name__])[0]
        raise UserError(f"{m['path']}: options.dbc: {path} cannot be decoded with "
                        f"{', '.join(d.name for d in m['dbc'])}: {first}") from None
    finally:
        mdf.close()
    return decoded


def _occurrences(mdf, label: str) -> tuple[str, list]:
    """(channel name, [(group, index), …]) of a source label (``name`` or ``name@GROUP``)."""
    occ = list(mdf.channels_db.get(label, ()))
    if occ or "@" not in label:
        return label, occ
    name, group = label.rsplit("@", 1)
    if not group.isdigit():
        return label, []
    return name, [o for o in mdf.channels_db.get(name, ()) if o[0] == int(group)]


def _signal(mdf, path: Path, label: str, m: dict, raw: bool = False):
    """The channel a source label names; a UserError names a missing or ambiguous one."""
    name, occ = _occurrences(mdf, label)
    if not occ:
        names = [n for n in mdf.channels_db if n not in ("time", "t")]
        close = difflib.get_close_matches(label, names, n=3, cutoff=0.6)
        hint = (f" (close: {', '.join(close)})" if close else
                f" (its DBC files {', '.join(d.name for d in m['dbc'])} decode no message of this file)"
                if not names and m.get("dbc") else
                f" ({len(names)} channels, e.g. {', '.join(names[:5])}"
                + ("; a raw bus log needs its DBC files: options.dbc" if not m.get("dbc")
                   and any(n.startswith("CAN_DataFrame") for n in names) else "") + ")")
        raise UserError(f"{path}: no channel '{label}' named in {m['path']}{hint}")
    if len(occ) > 1:
        raise UserError(f"{path}: channel '{label}' named in {m['path']} is in {len(occ)} channel "
                        f"groups: name one as {', '.join(f'{name}@{g}' for g, _ in occ[:4])}")
    g, i = occ[0]
    return mdf.get(name, group=g, index=i, raw=raw)


def _is_state(sig, e: dict) -> bool:
    """Whether a channel is a state, held between its samples: integer or boolean, with no
    physical unit (a gear, a mode, a flag). An integer with a unit is a measured value
    logged in whole units (a DBC's km/h or kPa at factor 1): linear in time like a float."""
    if np.asarray(sig.samples).dtype.kind not in "biu":
        return False
    u = lookup_unit(e["unit"] if e.get("unit") is not None else str(sig.unit or ""))
    return u is None or u[0] == "dimensionless"


def _numbers(sig, path: Path, label: str) -> np.ndarray:
    x = np.asarray(sig.samples)
    if x.dtype.kind == "b":
        return x.astype(float)
    if x.dtype.kind not in "iuf" or x.ndim != 1:
        v = x[0].item() if x.size and x.ndim == 1 else None
        v = v.decode("utf-8", "replace") if isinstance(v, bytes) else v
        what = repr(v) if v is not None else f"values of type {x.dtype}"
        raise UserError(f"{path}: channel '{label}' holds {what}: not a number (a text or "
                        "array channel cannot be mapped)")
    return x.astype(float)


def _conversion(m: dict, label: str, file_unit: str, path: Path) -> dict:
    """A mapped label's conversion: the mapping's unit, else the channel's unit in the file."""
    from sumo_drvpw.data.adapters.unit_names import _entry

    e = m["columns"][label]
    if e["unit"] is not None:
        return e
    try:
        return _entry(m["path"], e["key"], e["name"], file_unit, e["scale"])
    except UserError as err:
        raise UserError(f"{path}: channel '{label}' has the unit {file_unit!r} in the file, "
                        f"which does not fit '{e['name']}' ({str(err).split(': ', 2)[-1]}): give "
                        f"{e['key']}.unit in {m['path']}") from None


def read_file(path: Path, m: dict, parts: list[Path] | None = None) -> tuple[pd.DataFrame, dict]:
    """One MDF file through the mapping ``m`` (:func:`~sumo_drvpw.data.adapters.columns.load_mapping`
    with ``mdf=True``) → canonical frame and report; or, with ``parts``, the files of one
    folder (``path``) joined in time as one trip named after it."""
    from sumo_drvpw.data.adapters.labels import for_file, nor_others

    labels = {e["name"]: label for label, e in m["columns"].items()}
    for name in ("time_s", "trip_id"):
        if name in labels:
            raise UserError(f"{m['path']}: columns.{labels[name]!r} maps '{name}': an MDF file "
                            + ("carries its own time base (the speed channel's time stamps): "
                               if name == "time_s" else "is one trip, named after the file: ")
                            + "leave it unmapped")
    out: dict[str, np.ndarray] = {}
    missing, notes, averaged, fast_raw = [], [], [], {}
    mdf = _open(path, m, parts, notes)
    try:
        # of a column's labels (other loggers'), the first channel this file holds
        m, chosen_notes, _ = for_file(m, lambda lb: bool(_occurrences(mdf, lb)[1]), path)
        notes += chosen_notes
        for label, e in m["columns"].items():
            if e["name"] in m.get("candidates", {}) and not _occurrences(mdf, label)[1]:
                raise UserError(f"{path}: no channel '{label}' named in {m['path']}{nor_others(m, label)}")
        labels = {e["name"]: label for label, e in m["columns"].items()}
        speed = _signal(mdf, path, labels["speed_mps"], m)
        ts = np.asarray(speed.timestamps, float)
        for label, e in m["columns"].items():
            sig = speed if e["name"] == "speed_mps" else _signal(mdf, path, label, m)
            if np.asarray(sig.samples).dtype.kind in "SUO":  # texts by the file's value table
                raw = _signal(mdf, path, label, m, raw=True)
                if np.asarray(raw.samples).dtype.kind in "biu":
                    texts = ", ".join(sorted({v.decode("utf-8", "replace") if isinstance(v, bytes) else str(v)
                                              for v in np.asarray(sig.samples)[:1000]})[:4])
                    notes.append(f"channel '{label}': the file's value table reads it as texts ({texts}"
                                 ", …): its raw numbers are taken")
                    sig = raw
            conv = _conversion(m, label, str(sig.unit or ""), path)
            x = _numbers(sig, path, label)
            own = np.isin(x, e.get("na_num", ()))
            if "valid" in e:  # the channel's validity flag, at the channel's own samples
                flag = _signal(mdf, path, e["valid"], m, raw=True)
                fx = held(np.asarray(sig.timestamps, float), np.asarray(flag.timestamps, float),
                          _numbers(flag, path, e["valid"]))
                flagged = np.nan_to_num(fx) == 0
                own |= flagged
                if (n := int(flagged.sum())):
                    notes.append(f"channel '{label}': {n} sample(s) flagged invalid by '{e['valid']}': read as missing")
            x = np.where(own, np.nan, x)
            if e["name"] != "speed_mps":
                tc = np.asarray(sig.timestamps, float)
                if _is_state(sig, e):
                    x = held(ts, tc, x)
                else:
                    fast, mean = onto(ts, tc, x)
                    if mean:
                        averaged.append(label)
                        if e["name"] in POWER_FACTORS:  # its own samples, for keep_power
                            fast_raw[e["name"]] = (tc, x * conv["factor"] + conv["offset"])
                    x = fast
                if len(x) and (share := float(np.mean(~np.isfinite(x)))) > 0:
                    missing.append(f"{label} {100 * share:.2g} %")
            out[e["name"]] = x * conv["factor"] + conv["offset"]
    finally:
        mdf.close()
    notes += [f"channel '{labels[a]}' ({a}) is its mean weighted by '{labels[b]}' ({b}) over each speed "
              f"interval, so that {a} × {b} carries the mean power" for a, b in keep_power(ts, fast_raw, out)]
    trip = path.stem if parts is None else path.name
    rep = new_report(path, trip, len(ts))
    if parts is not None:
        rep["parts"] = len(parts)
        rep["notes"].append(f"{len(parts)} MDF files joined in time as one trip: "
                            f"{', '.join(p.name for p in parts[:3])}" + (", …" if len(parts) > 3 else ""))
    rep["notes"].append(
        f"ASAM MDF: {len(out) - 1} channel(s) put onto the {len(ts)} samples of the speed channel "
        f"'{labels['speed_mps']}' (states held; measured values {how(averaged)})"
        + (f"; missing: {', '.join(missing)}" if missing else ""))
    rep["notes"].extend(notes)
    df = pd.DataFrame({"time_s": ts, **out})
    df = clean_time_and_speed(df, path, rep)
    df.insert(0, "trip_id", trip)
    return df.reset_index(drop=True), rep


def channels(path: Path, m: dict) -> tuple[list[dict], list[str]]:
    """What an MDF file offers, to write a mapping from (``import columns SRC --list``): per
    channel its label (``name@GROUP`` where several groups carry the name), unit, samples,
    median sampling rate [Hz] and mean rate over the group's time span [Hz] (below the median
    where the channel comes in bursts with gaps between) — raw CAN frames decoded with the
    mapping's DBC files first — and the notes of the decoding."""
    notes: list[str] = []
    mdf = _open(path, m, None, notes)
    try:
        rows = []
        masters = getattr(mdf, "masters_db", {})
        for g, grp in enumerate(mdf.groups):
            n = int(grp.channel_group.cycles_nr)
            if not n:
                continue
            t = np.asarray(mdf.get_master(g), float)
            d = np.diff(t)
            step = float(np.median(d[d > 0])) if (d > 0).any() else float("nan")
            span = float(t[-1] - t[0]) if len(t) > 1 else 0.0
            mean_hz = (len(t) - 1) / span if span > 0 else float("nan")
            for i, ch in enumerate(grp.channels):
                if masters.get(g) == i or ch.name in ("time", "t"):
                    continue
                label = ch.name if len(mdf.channels_db.get(ch.name, ())) < 2 else f"{ch.name}@{g}"
                rows.append({"label": label, "unit": str(getattr(ch, "unit", "") or ""), "samples": n,
                             "rate_hz": 1.0 / step if step > 0 else float("nan"), "mean_rate_hz": mean_hz})
    finally:
        mdf.close()
    if not m.get("dbc") and any(r["label"].startswith("CAN_DataFrame") for r in rows):
        notes.append("raw CAN frames: name the vehicle's DBC files as options.dbc in a mapping file "
                     "to list their signals")
    return rows, notes
