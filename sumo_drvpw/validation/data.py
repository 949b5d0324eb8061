"""The real data sets of the validation, loaded the way every command loads a log.

A data set is a folder of ``../shared/data`` read in place by its adapter
(:mod:`sumo_drvpw.data.adapters`), turned into a canonical drive log
(:func:`sumo_drvpw.data.log.from_frame`) and measured by
:func:`sumo_drvpw.data.measured.measure`, the same code ``calibrate``, ``compare`` and
``diagnose`` use, so the validation sees the same usable samples they would.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, fields
from functools import cached_property
from pathlib import Path

import numpy as np

from sumo_drvpw.data.measured import Measured, measure
from sumo_drvpw.errors import UserError

#: data-set folder → (adapter format, vehicle)
DATASETS = {
    "bmw_i3_tum": ("bmw-i3-tum", "bmw_i3"),
    "prius_gen2_torquepro": ("torquepro-prius2", "prius2"),
    "jlu_bev_dyno": ("jlu-dyno", "jlu_bev"),
}


def positional(argv, usage: str) -> list[str]:
    """The arguments of a ``python -m sumo_drvpw.validation.X`` report generator, which are
    positional only (``usage``: e.g. "REPORT.md [DATA_FOLDER]"); a dashed one is refused
    (a help request was written to a report named after it)."""
    args = [str(a) for a in argv]
    for a in args:
        if a.startswith("-"):
            raise UserError(f"the arguments are positional, {usage}; got {a!r}")
    return args


def resolve_data(folder=None, datasets=DATASETS) -> Path:
    """The data folder: ``folder`` if given, else $SUMO_DRVPW_DATA, else <repo>/../shared/data.

    Raises :class:`UserError` naming the folder (and how it was chosen) when it or one of
    the ``datasets`` sub-folders is missing.
    """
    from sumo_drvpw.fileio import repo_root

    if folder:
        p, how = Path(folder), "data folder"
    elif os.environ.get("SUMO_DRVPW_DATA"):
        p, how = Path(os.environ["SUMO_DRVPW_DATA"]), "data folder $SUMO_DRVPW_DATA"
    else:
        p, how = repo_root().parent / "shared" / "data", "default data folder <repo>/../shared/data"
    if not p.is_dir():
        raise UserError(f"{how} not found: {p}")
    missing = [d for d in datasets if not (p / d).is_dir()]
    if missing:
        raise UserError(f"{how} {p}: missing data set folder(s) {', '.join(missing)} "
                        f"(expected {', '.join(datasets)})")
    return p


@dataclass
class Dataset(Measured):
    """One data set as the models see it: a :class:`Measured` log plus its folder name
    and the adapter's import report."""

    name: str = ""
    import_report: dict = field(default_factory=dict)

    @cached_property
    def trip(self) -> np.ndarray:
        """Trip id per sample (text)."""
        return self.log.df["trip_id"].to_numpy().astype(str)

    @cached_property
    def dt(self) -> np.ndarray:
        """Duration of each sample [s]."""
        return self.log.df["dt_s"].to_numpy(float)

    def provenance(self) -> dict:
        """What every data-set section reports first: source, import report, reader counts,
        and the median sampling rate [Hz] (within trips)."""
        t = self.log.df["time_s"].to_numpy(float)
        trip = self.trip
        steps = np.diff(t)[trip[1:] == trip[:-1]]
        return {"target": self.source, "import": self.import_report,
                "read_counts": {k: self.log.counts[k] for k in ("rows", "trips", "grade_source",
                                                                "accel_source", "excluded_total")},
                "sample_rate_hz": float(1.0 / np.median(steps)) if steps.size else None}


def load_dataset(data: Path, folder: str) -> Dataset:
    """Adapter → canonical drive log → measured power, inputs, usable mask.

    Parameters
    ----------
    data : the shared data folder; folder : one key of ``DATASETS``
    """
    from sumo_drvpw.data import adapters
    from sumo_drvpw.data.log import from_frame
    from sumo_drvpw.model.vehicles import load_vehicle

    fmt, vname = DATASETS[folder]
    veh = load_vehicle(vname)
    df, rep = adapters.read(fmt, data / folder)
    m = measure(from_frame(df, veh, name=str(data / folder)), veh)
    short = {"rows_read": rep["rows_read"], "kept": rep["kept"], "dropped": rep["dropped"],
             "files": len(rep["files"])}
    return Dataset(**{f.name: getattr(m, f.name) for f in fields(Measured)},
                   name=folder, import_report=short)


def compare_on(ds: Dataset, mask: np.ndarray, equations, reference=None):
    """:func:`sumo_drvpw.fit.compare.compare` of ``equations`` on the samples ``mask``."""
    from sumo_drvpw.fit.compare import compare

    return compare(ds.power_w[mask], ds.inputs.take(mask), equations, dt_s=ds.dt[mask],
                   reference=reference)


def metrics_row(comp, name: str) -> dict:
    """The metrics every validation table shows for one equation of a comparison."""
    r = comp.results[name]
    m = r.metrics
    return {"n": m["n"], "r2": m["r2"], "r2_light": m["r2_light"], "r2_heavy": m["r2_heavy"],
            "n_light": m["n_light"], "n_heavy": m["n_heavy"], "rmse_w": m["rmse_w"],
            "bias_w": m["bias_w"], "traction_energy_ratio": r.traction_energy_ratio}


def coefficient_block(eq) -> dict:
    """Coefficient and standard error per term of an equation."""
    return {t: {"coef": float(c), "std_err": eq.std_err.get(t)} for t, c in eq.terms.items()}


def vehicle_table(vehicle, table: str) -> dict:
    """A table of a vehicle file (e.g. ``road_load``); empty when absent."""
    from sumo_drvpw.fileio import read_toml

    return read_toml(vehicle.path, "vehicle file").get(table, {})


def vehicle_ref(vehicle) -> str:
    """The vehicle file relative to the repository when it lives there (stable across
    checkouts), else its file name."""
    from sumo_drvpw.fileio import repo_root

    p = Path(vehicle.path).resolve()
    try:
        return str(p.relative_to(repo_root()))
    except ValueError:
        return p.name


@dataclass
class StudyResult:
    """What one study returns: data only, rendered by :mod:`sumo_drvpw.validation.render`.

    Attributes
    ----------
    summary : the study's section of ``summary.json`` (JSON-ready numbers, SI)
    mask : the samples on which the study's own equations are evaluated against every
        built-in (held-out test samples where there is a split)
    equations : the study's calibrated or physical equations, for that table
    figures : file names of the figures written into the output folder
    settings : entries for the ``settings`` section of ``summary.json``
    """

    summary: dict
    mask: np.ndarray
    equations: list
    figures: list[str] = field(default_factory=list)
    settings: dict = field(default_factory=dict)
