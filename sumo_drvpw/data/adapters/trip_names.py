"""Trip ids that several files of one import share, made unique: a trip column's numbers
(1, 2, … per vehicle or per day, one file each) by the file's stem, and the files of one
name in several folders (``a/log.csv``, ``b/log.csv``: a trip named after the file, or a
trip column's) by their folder. Ids still shared after both are refused by the import."""

from __future__ import annotations

import os
from collections import Counter
from pathlib import Path

import pandas as pd


def in_several(ids: list[set]) -> set:
    """The ids found in more than one of the files' sets ``ids`` (each file's trip ids)."""
    return {i for i, n in Counter(i for s in ids for i in s).items() if n > 1}


def _some(ids) -> str:
    ids = sorted(ids, key=lambda x: (len(x), x))
    return f"{', '.join(ids[:3])}{' …' if len(ids) > 3 else ''}"


def qualify_shared_trips(frames: list[pd.DataFrame], reports: list[dict]) -> list[pd.DataFrame]:
    """Trip ids that a trip column gives in more than one file (trips numbered 1, 2, … per
    vehicle or per day, one file each) made unique: every trip of such a file named
    ``<file stem>-<trip>``, said in its notes. Before, the files' trips of one number were
    written as one trip (its rows from both files, its time running twice), which every
    command then refused."""
    ids = [set(map(str, pd.unique(f["trip_id"]))) for f in frames]
    shared = in_several(ids)
    if not shared:
        return frames
    out = []
    for f, r, s in zip(frames, reports, ids):
        if s & shared:
            stem = Path(r["file"]).stem
            f = f.copy()
            f["trip_id"] = stem + "-" + f["trip_id"].astype(str)
            both = sorted(s & shared, key=lambda x: (len(x), x))
            r["notes"].append(f"trip id(s) {_some(both)} also in another "
                              f"file: this file's trips named '{stem}-<trip>' (e.g. '{stem}-{both[0]}')")
            r["trip_id"] = ",".join(map(str, pd.unique(f["trip_id"])))
        out.append(f)
    return out


def qualify_by_folder(frames: list[pd.DataFrame], reports: list[dict], ids: list[set]) -> tuple[list, list[set]]:
    """Files of one stem in several folders that share a trip id (``a/log.csv`` and
    ``b/log.csv``, each a trip ``log`` or each numbering its trips 1, 2, …) made apart: every
    trip of such a file named ``<folder>-<trip>``, the folder its path below the files' common
    folder (``a``, ``b``; parts joined by ``-``), said in its notes, as files of other names
    are by their stem. ``ids``: each file's trip ids (a frame without a trip column: its
    report's). Returns (frames, ids) with the new names; other files as they were."""
    shared = in_several(ids)
    if not shared:
        return frames, ids
    by_stem: dict[str, list[int]] = {}
    for k, r in enumerate(reports):
        if ids[k] & shared:
            by_stem.setdefault(Path(r["file"]).stem, []).append(k)
    frames, ids = list(frames), list(ids)
    for ks in by_stem.values():
        dirs = [Path(os.path.abspath(reports[k]["file"])).parent for k in ks]
        here = in_several([ids[k] for k in ks])
        if len(set(dirs)) < 2 or not here:
            continue
        top = Path(os.path.commonpath(dirs))
        for k, d in zip(ks, dirs):
            both = ids[k] & here
            if not both:
                continue
            label = "-".join(d.relative_to(top).parts) or d.name or "root"
            r = reports[k]
            if "trip_id" in frames[k]:
                frames[k] = frames[k].copy()
                frames[k]["trip_id"] = label + "-" + frames[k]["trip_id"].astype(str)
            ids[k] = {f"{label}-{i}" for i in ids[k]}
            r["trip_id"] = ",".join(sorted(ids[k])) if "trip_id" in frames[k] else f"{label}-{r['trip_id']}"
            r["notes"].append(f"trip id(s) {_some(both)} also from a file of this name in another folder: "
                              f"this file's trips named '{label}-<trip>' (e.g. '{label}-{min(both)}')")
    return frames, ids
