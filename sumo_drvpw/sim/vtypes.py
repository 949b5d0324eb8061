"""vType data from SUMO route/additional files: explicit mass and drvpw.* parameters.

"Without mass" means: the vType definition carries neither a ``mass`` attribute nor a
``<param key="drvpw.mass">``, and the scenario gives no ``vtypes.<id>.mass_kg``. SUMO
itself would then use a default (``vehicletype.getMass`` says 1500 kg, the Energy model
1830 kg), so asking SUMO cannot tell an explicit mass from a default one; the files are
read instead.
"""

from __future__ import annotations

import gzip
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from sumo_drvpw.errors import UserError


@dataclass
class VTypeInfo:
    """What the files say about one vType: mass [kg] (None: not given), equation, source."""

    id: str
    mass_kg: float | None
    equation: str | None
    source: str


def _open(path: Path):
    with open(path, "rb") as f:
        magic = f.read(2)
    return gzip.open(path, "rb") if magic == b"\x1f\x8b" else open(path, "rb")


def read_vtypes(files: list[Path]) -> dict[str, VTypeInfo]:
    """Read every ``<vType>`` of the given route/additional files.

    Mass precedence: param ``drvpw.mass`` > attribute ``mass``.
    """
    out: dict[str, VTypeInfo] = {}
    for path in files:
        try:
            with _open(path) as fh:
                for _, el in ET.iterparse(fh, events=("end",)):
                    tag = el.tag.split("}")[-1]
                    if tag != "vType":
                        if tag not in ("param",):
                            el.clear()
                        continue
                    vid = el.attrib.get("id")
                    if vid is None:
                        continue
                    params = {p.attrib.get("key"): p.attrib.get("value")
                              for p in el if p.tag.split("}")[-1] == "param"}
                    where = f"{path}: vType '{vid}'"
                    mass = None
                    for key, val in (("mass", el.attrib.get("mass")),
                                     ("drvpw.mass", params.get("drvpw.mass"))):
                        if val is None:
                            continue
                        try:
                            mass = float(val)
                        except ValueError:
                            raise UserError(f"{where}: {key} is not a number: {val!r}") from None
                        if not mass > 0:
                            raise UserError(f"{where}: {key} must be > 0, got {val!r}")
                    out[vid] = VTypeInfo(vid, mass, params.get("drvpw.equation") or None,
                                         str(path))
                    el.clear()
        except ET.ParseError as e:
            raise UserError(f"{path}: not valid XML: {e}") from None
        except OSError as e:
            raise UserError(f"{path}: cannot read: {e}") from None
    return out
