"""Build the bundled networks from their plain-XML sources with netconvert.

Usage: python networks/build.py   (writes sumo_drvpw/sim/builtin/networks/<name>.net.xml,
the package data the built-in scenarios and `sumo-drvpw demo` use)

Each network has ``src/<name>.nod.xml`` (nodes with elevation z [m]), ``src/<name>.edg.xml``
and the shared ``src/types.typ.xml`` (OSM-style edge types ``highway.*`` with speed
limits). ``--precision 4`` keeps z to 0.1 mm: netconvert's default rounds z to cm, which
turns a 2 % grade into 1.148° instead of 1.146° (see /work/shared/design.md).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
OUT = HERE.parent / "sumo_drvpw" / "sim" / "builtin" / "networks"
NETWORKS = ("city", "highway")


def build(name: str) -> Path:
    """Run netconvert for one network; return the path of the built .net.xml."""
    import sumo
    import sumolib

    src = HERE / "src"
    out = OUT / f"{name}.net.xml"
    cmd = [sumolib.checkBinary("netconvert"),
           "--node-files", str(src / f"{name}.nod.xml"),
           "--edge-files", str(src / f"{name}.edg.xml"),
           "--type-files", str(src / "types.typ.xml"),
           "--precision", "4",
           "--offset.disable-normalization", "true",
           "--no-turnarounds", "true",
           "--tls.default-type", "static",
           "--output.street-names", "false",
           "--no-warnings", "true",
           "-o", str(out)]
    env = dict(os.environ, SUMO_HOME=sumo.SUMO_HOME)
    subprocess.run(cmd, check=True, env=env, cwd=HERE)
    return out


def main(argv: list[str]) -> int:
    for name in argv or NETWORKS:
        print("built", build(name))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
