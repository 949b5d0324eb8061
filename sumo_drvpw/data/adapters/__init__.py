"""Adapters: vendor drive logs → canonical drive logs (../shared/spec/drive-log.md).

``read(format, paths, columns=None) -> (DataFrame, report)`` is the one entry point; the
CLI ``sumo-drvpw import`` wraps it. FORMATS maps each format name to its reader module.
The report counts, per file and in total, the rows read, kept and dropped per reason, and
lists the roles the adapter declares for its columns (``report["roles"]``, stored with the
log as ``drive_log.roles``; see :mod:`sumo_drvpw.data.roles`).
"""

from __future__ import annotations

import importlib

from sumo_drvpw.errors import UserError

#: format name → module (each has read(paths) → (frames, reports, notes); columns also takes the mapping)
FORMATS = {
    "bmw-i3-tum": "sumo_drvpw.data.adapters.bmw_i3_tum",
    "torquepro": "sumo_drvpw.data.adapters.torquepro_prius2",
    "torquepro-prius2": "sumo_drvpw.data.adapters.torquepro_prius2",
    "jlu-dyno": "sumo_drvpw.data.adapters.jlu_dyno",
    "jlu-road": "sumo_drvpw.data.adapters.jlu_road",
    "car-scanner": "sumo_drvpw.data.adapters.car_scanner",
    "columns": "sumo_drvpw.data.adapters.columns",
}


def read(format: str, paths, columns=None):
    """Read vendor files of one format into a canonical drive log.

    format: one of FORMATS; paths: file or folder, or a list of them; columns: mapping TOML
    path (format 'columns' only). Returns (DataFrame in SI with canonical names, report dict).
    """
    if format not in FORMATS:
        raise UserError(f"unknown format '{format}': use one of {', '.join(FORMATS)}")
    from sumo_drvpw.data.adapters._common import TRUNCATED, WIDER_ROWS

    TRUNCATED.clear()  # what an earlier read left (an adapter refused a file before its report
    WIDER_ROWS.clear()  # took the file's marks): each read says its own
    mod = importlib.import_module(FORMATS[format])
    if format == "columns":
        frames, reports, notes = mod.read(paths, columns)
    else:
        if columns is not None:
            raise UserError(f"a column mapping is only for format 'columns', not '{format}'")
        frames, reports, notes = mod.read(paths)
    from sumo_drvpw.data.adapters._common import combine

    df, report = combine(format, frames, reports, notes)
    declared = dict(getattr(mod, "ROLES", {}))
    if format == "columns":
        declared.update(mod.mapping_roles(columns))
    report["roles"] = {c: r for c, r in declared.items() if c in df.columns}
    return df, report
