"""Where a scenario is: a scenario file or SUMO config given by its path, or one of the
built-in scenarios (package data, ``sim/builtin/scenarios``) given by its name; and the
files a SUMO config names (:func:`config_files`)."""

from __future__ import annotations

import os
import re
import xml.etree.ElementTree as ET
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
    if not isinstance(spec, (str, os.PathLike)):
        raise UserError(f"scenario: give a scenario file, a SUMO config or a built-in scenario's name "
                        f"({', '.join(builtin_scenario_names())}), got {spec!r}")
    p = Path(spec)
    if p.is_dir():  # a scenario folder: name its SUMO configs and scenario files
        raise UserError(folder_given(p, "scenario", (".sumocfg", ".toml")))
    if p.exists() or p.suffix in (".toml", ".sumocfg") or any(c in str(spec) for c in "/\\"):
        return p
    return bundled_scenario(str(spec))


def sumo_file_list(value) -> list[str]:
    """The files of a SUMO file-list option ("a.xml, b.xml"), each stripped, also where
    SUMO put its config's folder before a name the config gave after ", ": a config given
    by a path from another folder reports its list as "dir/a.xml,dir/ b.xml" (getOption,
    an FCD's header), and SUMO itself loads dir/b.xml."""
    out = []
    for f in str(value or "").split(","):
        # the space SUMO leaves after its config's folder, before the name as the config wrote
        # it (which may hold folders of its own: "dir/ sub/b.xml")
        f = re.sub(r"^(.*?[/\\])\s+(?=\S)", r"\1", f.strip())
        if f:
            out.append(f)
    return out


def config_files(cfg: Path) -> tuple[Path, list[Path], dict[str, str]]:
    """Net file, route+additional files and time values named in a SUMO config."""
    try:
        root = ET.parse(cfg).getroot()
    except ET.ParseError as e:
        raise UserError(f"SUMO config {cfg}: not valid XML: {e}") from None
    except OSError as e:
        raise UserError(f"SUMO config {cfg}: cannot read: {e}") from None
    vals: dict[str, str] = {}
    for el in root.iter():
        tag = el.tag.split("}")[-1]
        if "value" in el.attrib:
            vals[tag] = el.attrib["value"]
    net = vals.get("net-file")
    if not net:
        raise UserError(f"SUMO config {cfg}: no <net-file>")
    files = []
    for key in ("route-files", "additional-files"):
        for f in sumo_file_list(vals.get(key, "")):
            files.append((cfg.parent / f).resolve())
    return (cfg.parent / net).resolve(), files, vals
