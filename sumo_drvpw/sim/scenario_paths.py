"""Where a scenario is: a scenario file or SUMO config given by its path, or one of the
built-in scenarios (package data, ``sim/builtin/scenarios``) given by its name."""

from __future__ import annotations

from pathlib import Path

from sumo_drvpw.errors import UserError
from sumo_drvpw.fileio import folder_given


#: Built-in scenarios (package data): ``sumo-drvpw run city`` / ``highway``, the demo's.
BUILTIN_SCENARIOS = Path(__file__).resolve().parent / "builtin" / "scenarios"


def builtin_scenario_names() -> list[str]:
    return sorted(p.stem for p in BUILTIN_SCENARIOS.glob("*.toml"))


def bundled_scenario(name: str) -> Path:
    """The built-in scenario ``name`` (package data); UserError naming the known ones."""
    p = BUILTIN_SCENARIOS / f"{name}.toml"
    if not p.is_file():
        raise UserError(f"unknown built-in scenario '{name}' (built-ins: "
                        f"{', '.join(builtin_scenario_names())})")
    return p


def scenario_path(spec) -> Path:
    """A scenario file path, or a built-in scenario's when ``spec`` names one and no file."""
    p = Path(spec)
    if p.is_dir():  # a scenario folder: name its SUMO configs and scenario files
        raise UserError(folder_given(p, "scenario", (".sumocfg", ".toml")))
    if p.exists() or p.suffix in (".toml", ".sumocfg") or any(c in str(spec) for c in "/\\"):
        return p
    return bundled_scenario(str(spec))
