"""The validation runner: every study on its data set, then the report.

Reads the real data sets in place (``../shared/data``, never copied), runs each study in
``STUDIES`` on its data set (loaded once, :mod:`sumo_drvpw.validation.data`), then the
all-equations table, and writes ``summary.json`` and PNG figures into ``<out>/`` and the
Markdown report ``<out>.md`` beside it (``docs/validation`` → ``docs/validation.md``).
Every number in the report is computed by this run.

To add a study: a module with ``DATASET`` (a key of ``data.DATASETS``) and
``study(ds, out) -> StudyResult``, a section renderer ``(section, rel) -> lines``, and
one :class:`Study` line in ``STUDIES``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from sumo_drvpw.model.constants import HEAVY_LOAD_W
from sumo_drvpw.validation import all_equations, i3, jlu, prius2, render
from sumo_drvpw.validation.data import Dataset, StudyResult, load_dataset


@dataclass(frozen=True)
class Study:
    """One section of the validation.

    Attributes
    ----------
    key : the section's key in ``summary.json``
    dataset : the data-set folder it reads (a key of ``data.DATASETS``)
    run : ``(dataset, out folder) → StudyResult``
    render : ``(section, figure folder name) → Markdown lines``
    label : short name of the data set in the report header
    in_all_equations : whether its mask and equations feed the all-equations table (one
        study per data set)
    """

    key: str
    dataset: str
    run: Callable[[Dataset, Path], StudyResult]
    render: Callable[[dict, str], list[str]]
    label: str
    in_all_equations: bool = True


#: The studies, in report order.
STUDIES: list[Study] = [
    Study("bmw_i3", i3.DATASET, i3.study, render.i3_section, "i3"),
    Study("prius2", prius2.DATASET, prius2.study, render.prius2_section, "Prius"),
    Study("jlu", jlu.DATASET, jlu.study, render.jlu_section, "dyno"),
]


def report_path(out: Path) -> Path:
    """``<out>.md`` beside the figure folder ``out``."""
    out = Path(out)
    return out.parent / f"{out.name}.md"


def run_validation(data: Path, out: Path, command: str = "", studies=None,
                   chain: bool = False) -> dict:
    """Run every study, write figures, ``summary.json`` and ``<out>.md``; return the summary.

    Parameters
    ----------
    data : the shared data folder (``data.resolve_data``)
    out : folder for figures and ``summary.json``; the report is ``<out>.md``
    command : the command line, quoted in the report
    studies : the studies to run (default ``STUDIES``)
    chain : also the energy-chain study (:mod:`sumo_drvpw.validation.chain`: battery and
        fuel energy per held-out trip beside SUMO's own models, issue #12; 1–4 min
        more), under ``energy_chain`` in the summary and as the report's last section
    """
    from sumo_drvpw.fileio import plain, write_json, write_text

    studies = STUDIES if studies is None else studies
    t0 = time.perf_counter()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    figures: list[str] = []
    datasets: dict[str, Dataset] = {}
    results: dict[str, StudyResult] = {}
    sections, timing = {}, {}
    settings = {"heavy_load_w": HEAVY_LOAD_W, "error": "predicted - measured",
                "r2": "centred 1 - SSE/SST; light/heavy each on its own mean"}
    for st in studies:
        t = time.perf_counter()
        if st.dataset not in datasets:
            datasets[st.dataset] = load_dataset(data, st.dataset)
        res = st.run(datasets[st.dataset], out)
        sections[st.key] = res.summary
        figures += res.figures
        settings.update(res.settings)
        if st.in_all_equations:
            results[st.dataset] = res
        timing[st.key] = time.perf_counter() - t
    t = time.perf_counter()
    table = all_equations.study({k: datasets[k] for k in results}, results)
    timing["all_equations"] = time.perf_counter() - t
    if chain:
        from sumo_drvpw.validation import chain as chain_study

        t = time.perf_counter()
        sections["energy_chain"] = chain_study.run(data)
        timing["energy_chain"] = time.perf_counter() - t
    summary = {"run": {"command": command, "data": str(data), "seconds": None,
                       "section_seconds": timing},
               **sections,
               "all_equations": table,
               "figures": figures,
               "settings": settings}
    summary["run"]["seconds"] = time.perf_counter() - t0
    summary = plain(summary)
    write_json(out / "summary.json", summary)
    write_text(report_path(out), render.render(summary, out.name,
                                               [(st.key, st.render, st.label) for st in studies]))
    return summary
