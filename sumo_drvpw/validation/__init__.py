"""Validation on the shared real data: one study per data set, one renderer.

``data`` loads a data set the way every command loads a log; ``i3``, ``prius2``,
``jlu`` are the studies (each returns data), ``all_equations`` tabulates every equation
on every data set, ``render`` turns the summary into Markdown, and ``run`` is the runner
(``run_validation``) iterating ``STUDIES``.
"""

from sumo_drvpw.validation.data import DATASETS, resolve_data
from sumo_drvpw.validation.run import STUDIES, report_path, run_validation

__all__ = ["DATASETS", "STUDIES", "report_path", "resolve_data", "run_validation"]
