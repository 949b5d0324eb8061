"""Loading a SUMO network for a run (sim/network.py ``load_network``: sumolib's reader plus
every lane's slope profile, heading and centre line) against sumolib's reader alone, the
baseline measured in the same run: medians of ``--repeats`` loads. The load timed is
``read_network``, what ``load_network`` does when the table is not kept on disk
(sim/net_cache.py): the cache would make every repeat after the first a read of the kept file.

By default a grid built with SUMO's netgenerate (``--grid-number``² junctions, 2 lanes each
way, no elevation: most public scenarios' networks carry none); ``--net`` loads a given
network instead (e.g. a scenario's ``*.net.xml.gz``). A lane without z takes the flat profile
(no slope computation), so such a network's load is dominated by sumolib's reader.

    .venv/bin/python benchmarks/network_load.py --repeats 3
    .venv/bin/python benchmarks/network_load.py --net path/to/osm.net.xml.gz

Target: load_network / sumolib reader ≤ 2.5 on a network without elevation.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import tempfile
import time
from pathlib import Path


def _grid(folder: Path, n: int) -> Path:
    import sumolib

    out = folder / "grid.net.xml"
    subprocess.run([sumolib.checkBinary("netgenerate"), "--grid", "--grid.number", str(n),
                    "--grid.length", "200", "--default.lanenumber", "2", "-o", str(out),
                    "--no-warnings"], check=True, capture_output=True)
    return out


def _time(fn, repeats: int) -> list[float]:
    out = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--net", help="a SUMO network to load (default: a generated grid)")
    ap.add_argument("--grid-number", type=int, default=60, help="junctions per side of the grid")
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args()

    import sumolib

    from sumo_drvpw.sim.network import read_network
    from sumo_drvpw.sim.scenario import RoadClassRule

    with tempfile.TemporaryDirectory() as d:
        net = Path(a.net) if a.net else _grid(Path(d), a.grid_number)
        base = _time(lambda: sumolib.net.readNet(str(net), withInternal=True), a.repeats)
        ours = _time(lambda: read_network(net, RoadClassRule()), a.repeats)  # (not the kept table)
        n = read_network(net, RoadClassRule())
    b, o = statistics.median(base), statistics.median(ours)
    print(f"network {net.name}: {len(n.lane_ids)} lanes, z on {100 * n.z_share:.3g} % of their length")
    print(f"sumolib reader: median {b:.2f} s {[round(x, 2) for x in base]}")
    print(f"load_network:   median {o:.2f} s {[round(x, 2) for x in ours]}")
    print(f"ratio load_network / reader: {o / b:.2f}")


if __name__ == "__main__":
    main()
