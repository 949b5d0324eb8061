"""Drive-log files in: the files named and those inside folders named, and each file's table
read (Parquet, or UTF-8 CSV read up to a last row cut short) with its numeric and flag
columns parsed; errors name the file, column and first offending row, and say where a
vendor file goes (the import command). Validated and derived by sumo_drvpw.data.log."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from sumo_drvpw.data.paths import expand_paths as _expand_paths, parquet_frame
from sumo_drvpw.data.plausible import check_header
from sumo_drvpw.data.truncated import read_complete_csv
from sumo_drvpw.errors import UserError

#: Canonical numeric columns the reader checks when present.
NUMERIC = ("time_s", "speed_mps", "accel_mps2", "grade_rad", "grade_pct", "elevation_m",
           "wind_mps", "airspeed_mps", "air_density_kgm3", "ambient_c", "pressure_kpa",
           "mass_kg", "power_w", "ice_speed_rpm", "mg1_speed_rpm", "mg1_torque_nm",
           "mg2_speed_rpm", "mg2_torque_nm", "motor_torque_nm", "motor_speed_rpm",
           "battery_voltage_v", "battery_current_a", "yaw_rate_rps",
           "battery_discharge_energy_j", "battery_charge_energy_j")
REQUIRED, FLAGS = ("time_s", "speed_mps"), ("brake", "reverse")


def expand_paths(paths) -> list[Path]:
    """Files named, and the Parquet/CSV files inside folders named (sorted): the drive-log
    case of :func:`sumo_drvpw.data.paths.expand_paths` (a named file of another type is
    refused)."""
    return _expand_paths(paths, (".parquet", ".csv"), "drive log", check_files=True)


def vendor_hint() -> str:
    """Where a file that is no canonical drive log should go: an adapter of the import command."""
    from sumo_drvpw.data.adapters import FORMATS

    return f"vendor logs are converted by the import command first (formats: {', '.join(FORMATS)})"


def read_error(p: Path, e: Exception) -> UserError:
    """The one-line error of a table that cannot be read (text that is not UTF-8 named with
    its first offending byte, as a canonical CSV drive log is UTF-8)."""
    if isinstance(e, UnicodeDecodeError):
        return UserError(f"{p}: not UTF-8 text (byte 0x{e.object[e.start]:02x} at offset {e.start}); "
                         f"a canonical CSV drive log is UTF-8; {vendor_hint()}")
    return UserError(f"{p}: cannot read as {p.suffix[1:]}: {e}")


def _read_table(p: Path) -> tuple[pd.DataFrame, dict, int | None]:
    """A file's table, its Parquet metadata and, for a CSV cut inside its last row, that
    row's number (left out: :mod:`sumo_drvpw.data.truncated`; else None)."""
    meta, cut = {}, None
    try:
        if p.suffix.lower() == ".parquet":
            df, meta = parquet_frame(p, (b"sumo_drvpw", b"drive_log."))  # drive_log.roles: spec
        else:
            check_header(p)
            df, cut = read_complete_csv(p, low_memory=False)
    except pd.errors.EmptyDataError:
        raise UserError(f"{p}: empty file (no header, no rows)") from None
    except (OSError, ValueError, pd.errors.ParserError) as e:
        raise read_error(p, e) from None
    if len(df) == 0:
        raise UserError(f"{p}: empty table (header only, no samples)")
    return df, meta, cut


def _check_numeric(df: pd.DataFrame, p: Path) -> None:
    for c in NUMERIC:
        if c in df and (pd.api.types.is_datetime64_any_dtype(df[c]) or pd.api.types.is_timedelta64_dtype(df[c])):
            raise UserError(f"{p}: column '{c}' holds timestamps ({df[c].dtype}), not numbers; the "
                            "drive-log schema wants numbers in SI units (time_s: seconds, e.g. since the trip start)")
        if c not in df or pd.api.types.is_numeric_dtype(df[c]):
            continue
        conv = pd.to_numeric(df[c], errors="coerce")
        bad = conv.isna() & df[c].notna() & (df[c].astype(str).str.strip() != "")
        if bad.any():
            i = int(np.flatnonzero(bad.to_numpy())[0])
            raise UserError(f"{p}: column '{c}' has a non-numeric value {df[c].iloc[i]!r} "
                            f"at row {i}")
        df[c] = conv


def _check_flags(df: pd.DataFrame, p: Path) -> None:
    for c in FLAGS:
        if c not in df:
            continue
        col = df[c]
        if pd.api.types.is_bool_dtype(col):
            df[c] = col.fillna(False).astype(bool)
            continue
        s = col.astype(object).where(col.notna(), "").astype(str).str.strip().str.lower()  # NA: not set
        mapping = {"true": True, "false": False, "1": True, "0": False, "1.0": True,
                   "0.0": False, "yes": True, "no": False, "nan": False, "": False,
                   "none": False, "<na>": False}
        bad = ~s.isin(list(mapping))
        if bad.any():
            i = int(np.flatnonzero(bad.to_numpy())[0])
            raise UserError(f"{p}: column '{c}' must be boolean, got {col.iloc[i]!r} at row {i}")
        df[c] = s.map(mapping).astype(bool)

