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



def parking_steps_wh(scenario: Path, d: Path, vehicles=("p",), attr: str = "electricity",
                     before: float | None = None) -> dict:
    """What SUMO's emissions device books per vehicle of ``vehicles`` beyond its emission
    output over the two steps of each parking where the two part [Wh; mg for another
    ``attr``]: the step it parks in — SUMO moves the car on its lane into its stop, below
    0.1 m/s, then takes it off the road: the output (the vehicles on the road at the step's
    end) does not write it, the device books the move (MSDevice_Emissions::notifyMove) —
    and the step its parking ends — SUMO puts it back on its lane at speed 0 after the
    step's moves (MSVehicleTransfer::checkInsertions): the output writes it, the device
    books nothing. The output plus this is the device's count, which the plug-in books
    (sim/parking.py). Probe runs of ``scenario`` (its own command line, outputs into ``d``):
    one finds the steps in its FCD — the first row beside the lane (farther from its
    centre line than half its width) after one on it, the last before one on it — and,
    per such step, the device (tripinfo, unfinished trips written) ended before and after
    it gives its booking, the output its own. ``before``: only the steps before that time
    [s] (a script acts from then, which these runs do not)."""
    from sumolib.geomhelper import distancePointToPolygon
    from sumolib.net import readNet

    from sumo_drvpw.sim.scenario import load_scenario

    d.mkdir(parents=True, exist_ok=True)
    sc = load_scenario(scenario)
    args = list(sc.sumo_args)
    for opt in ("--emission-output", "--fcd-output", "--end"):  # (the scenario run's: kept)
        if opt in args:
            del args[args.index(opt):args.index(opt) + 2]

    def sumo(end: float, *out: str) -> None:
        subprocess.run([sumolib.checkBinary("sumo"), *args, "--end", f"{end:.6f}", *out], check=True,
                       capture_output=True)

    sumo(float(sc.end), "--emission-output", str(d / "em.xml"), "--fcd-output", str(d / "fcd.xml"))
    dt = float(sc.step_length)
    written = {(ts.get("time"), v.get("id")): float(v.get(attr)) * dt  # (per second written)
               for ts in ET.parse(d / "em.xml").getroot() for v in ts}
    net = readNet(str(sc.net_file))
    rows = defaultdict(list)
    for ts in ET.parse(d / "fcd.xml").getroot():
        for v in ts:
            if v.get("id") in vehicles:
                lane = net.getLane(v.get("lane"))
                beside = distancePointToPolygon((float(v.get("x")), float(v.get("y"))), lane.getShape()) \
                    > lane.getWidth() / 2 + 0.1
                rows[v.get("id")].append((ts.get("time"), beside))
    steps = []
    for vid, r in rows.items():
        r = [x for x in r if before is None or float(x[0]) < before - 1e-9]
        for (t0, b0), (t1, b1) in zip(r, r[1:]):
            if b1 and not b0:
                steps.append((t1, vid))  # parks in
            elif b0 and not b1:
                steps.append((t0, vid))  # its parking ends in
    out: dict = defaultdict(float)
    for t, vid in steps:
        out[vid] += device_step(scenario, d, float(t), vid, attr) - written.get((t, vid), 0.0)
    return out


def device_step(scenario: Path, d: Path, t: float, vid: str, attr: str = "electricity") -> float:
    """What SUMO's emissions device books for vehicle ``vid`` in the step the outputs write at
    time ``t`` [s] (``attr``: electricity [Wh], fuel [mg], …): its tripinfo (unfinished trips
    written) of two runs of ``scenario`` (its own command line; files in ``d``), ended at
    ``t`` and a step later."""
    from sumo_drvpw.sim.scenario import load_scenario

    sc = load_scenario(scenario)
    args = list(sc.sumo_args)
    for opt in ("--emission-output", "--fcd-output", "--end", "--tripinfo-output"):
        if opt in args:
            del args[args.index(opt):args.index(opt) + 2]
    dev = []
    for end in (t, t + float(sc.step_length)):
        subprocess.run([sumolib.checkBinary("sumo"), *args, "--end", f"{end:.6f}", "--tripinfo-output",
                        str(d / "ti.xml"), "--tripinfo-output.write-unfinished", "--device.emissions.explicit", vid],
                       check=True, capture_output=True)
        dev.append(next(float(e.find("emissions").get(f"{attr}_abs"))
                        for e in ET.parse(d / "ti.xml").getroot() if e.get("id") == vid))
    return dev[1] - dev[0]


def booked_per_vehicle(out: Path):
    """A run's (or replay's) booking per vehicle from its output folder ``out``: time and
    distance (vehicles.parquet) with its battery chain's auxiliary and net kWh
    (chain_vehicles.csv), sorted by vehicle."""
    import pandas as pd

    v = pd.read_parquet(out / "vehicles.parquet").set_index("vehicle")
    c = pd.read_csv(out / "chain_vehicles.csv").set_index("key")
    return v[["time_s", "distance_m"]].join(c[["auxiliary_kwh", "net_kwh"]]).sort_index()


def fcd_rise(net, rows):
    """Per vehicle: (profile elevation at its first row, at its last row, robust slope and
    speed at its first row) of FCD rows ``rows`` (sim/fcd.read_fcd) on network ``net``."""
    import pandas as pd

    from sumo_drvpw.sim.network import lane_numbers

    rows = rows[~rows["person"]].sort_values("time", kind="stable")
    lane = lane_numbers(net.lane_index, list(rows["lane"]))
    rows = rows.assign(z=net.elevation(lane, rows["pos"].to_numpy()),
                       theta=net.slope(lane, rows["pos"].to_numpy())[0])
    g = rows.groupby("id")
    return pd.DataFrame({"z0": g["z"].first(), "z1": g["z"].last(),
                         "theta": g["theta"].first(), "v": g["speed"].first()})


def tracked_getter_replay(sc: Path, fcd: Path, equations) -> dict:
    """Scenario ``sc`` booked three ways with ``equations``: the live run tracking positions
    (recording its FCD at 6 decimals to ``fcd``), the live run reading them by getters every
    step, and the replay of that FCD (RunResults by "tracked", "getter", "replay")."""
    from sumo_drvpw.sim import run_scenario
    from sumo_drvpw.sim.fcd import process_fcd

    kw = dict(equations=equations, figures=False)
    return {"tracked": run_scenario(sc, None, options=["--fcd-output", str(fcd), "--precision", "6"], **kw),
            "getter": run_scenario(sc, None, positions="getter", **kw),
            "replay": process_fcd(fcd, scenario=sc, **kw)}
