"""Shared set-up of the tests that hold a run against SUMO's own emission output: a small
network built by netconvert, a scenario TOML that has SUMO write its emission output (and
FCD) at 6 decimals, and SUMO's electricity per vehicle read back."""

from __future__ import annotations

import math
import subprocess
import xml.etree.ElementTree as ET
from collections import defaultdict
from pathlib import Path

import sumolib


def build_net(d: Path, nodes_xml: str, edges_xml: str, *options: str) -> Path:
    """``n.net.xml`` in ``d`` from the ``<nodes>`` and ``<edges>`` texts (netconvert options
    added)."""
    (d / "n.nod.xml").write_text(nodes_xml, encoding="utf-8")
    (d / "n.edg.xml").write_text(edges_xml, encoding="utf-8")
    subprocess.run([sumolib.checkBinary("netconvert"), "-n", "n.nod.xml", "-e", "n.edg.xml", "-o", "n.net.xml",
                    *options], check=True, capture_output=True, cwd=d)
    return d / "n.net.xml"


def energy_scenario(d: Path, end: float, step_length: float = 0.5, additional: str | None = None,
                    fcd: bool = True, routes: str = "r.rou.xml") -> Path:
    """``s.toml`` in ``d``: ``vtype_energy`` on ``n.net.xml`` and the route file, SUMO's
    emission output (``d/em.xml``) and, with ``fcd``, its FCD (``d/fcd.xml``) at 6 decimals."""
    outs = f'"--emission-output", "{d / "em.xml"}"' + (f', "--fcd-output", "{d / "fcd.xml"}"' if fcd else "")
    (d / "s.toml").write_text(
        f'equations = ["vtype_energy"]\n[sumo]\nnet = "n.net.xml"\nroutes = ["{routes}"]\n'
        + (f'additional = ["{additional}"]\n' if additional else "")
        + f'end = {end}\nstep_length = {step_length}\noptions = ["--no-warnings", "true", "--precision", "6", '
        f'{outs}]\n[outputs]\nfigures = false\n', encoding="utf-8")
    return d / "s.toml"


def emitted_wh(path: Path, dt: float) -> tuple[dict, dict]:
    """SUMO's emission output: electricity [Wh/s] × Δt summed per vehicle over the steps it
    computed [Wh], and the number of its nan steps per vehicle."""
    wh, nan = defaultdict(float), defaultdict(int)
    for ts in ET.parse(path).getroot():
        for v in ts:
            e = float(v.get("electricity"))
            if math.isnan(e):
                nan[v.get("id")] += 1
            else:
                wh[v.get("id")] += e * dt
    return wh, nan
