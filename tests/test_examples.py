"""The examples in the docstrings of the main entry points run and print what they say."""

from __future__ import annotations

import doctest
import importlib

import pytest


@pytest.mark.parametrize("module", ["sumo_drvpw.fit.ols", "sumo_drvpw.fit.calibrate",
                                    "sumo_drvpw.fit.compare", "sumo_drvpw.model.equations",
                                    "sumo_drvpw.model.air", "sumo_drvpw.report.format"])
def test_docstring_examples(module):
    mod = importlib.import_module(module)
    res = doctest.testmod(mod, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert res.attempted > 0, f"{module} has no example"
    assert res.failed == 0
