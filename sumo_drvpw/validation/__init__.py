"""Validation on the shared real data: one study per data set, one renderer.

``data`` loads a data set the way every command loads a log; ``i3``, ``prius2``,
``jlu`` are the studies (each returns data), ``all_equations`` tabulates every equation
on every data set, ``render`` turns the summary into Markdown, and ``run`` is the runner
(``run_validation``) iterating ``STUDIES``. The energy chains' validation
(docs/energy-chain-validation.md): ``chain`` (its runner), ``chain_common``, ``chain_i3``,
``chain_i3_heater``, ``chain_sumo`` (SUMO's Energy model and MMPEVEM beside the chains) and
``chain_render``. The built-in chains' sources, each writing its docs page and equation
files: ``epa_fleet`` (+ ``epa_fleet_report``, ``epa_cold``; docs/epa-fleet.md),
``epa_hybrid`` (docs/epa-hybrid.md) and ``hdv_fuel`` (+ ``hdv_fuel_report``; docs/hdv-fuel.md).
The loop closed on real data, held out (docs/closing-the-loop.md, run by
scripts/closing_the_loop.py): ``closing_the_loop`` (+ ``closing_the_loop_read``,
``closing_the_loop_fit``, ``closing_the_loop_checks``).
"""

from sumo_drvpw.validation.data import DATASETS, resolve_data
from sumo_drvpw.validation.run import STUDIES, report_path, run_validation

__all__ = ["DATASETS", "STUDIES", "report_path", "resolve_data", "run_validation"]
