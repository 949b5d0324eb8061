"""A script of the repository's scripts/ folder loaded as a module, for the tests of its
functions (the scripts are no package: each is loaded from its file, under its own name)."""

import importlib.util
from pathlib import Path

SCRIPTS = Path(__file__).resolve().parent.parent / "scripts"


def load_script(stem: str, as_name: str | None = None):
    """``scripts/<stem>.py`` as a fresh module named ``as_name`` (default the stem)."""
    spec = importlib.util.spec_from_file_location(as_name or stem, SCRIPTS / f"{stem}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod
