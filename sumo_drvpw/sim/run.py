"""Run a scenario: start SUMO, resolve vTypes, step the loop, write the outputs.

``run_scenario(scenario_path, out_dir, **overrides) -> summary`` runs a scenario file
(see :mod:`sumo_drvpw.sim.scenario`) with libsumo (or traci) and writes the outputs of
:mod:`sumo_drvpw.sim.outputs` into ``out_dir``. Modules: ``scenario`` (config), ``vtypes``
(mass and drvpw.* params from the route files), ``network`` (edge table, classes, robust
slopes), ``ledger`` (vectorized evaluation and accumulation), ``loop`` (the stepping loop,
connection passed in), ``outputs``.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from sumo_drvpw.errors import UserError

__all__ = ["run_scenario", "start_sumo", "close_sumo", "VTypeResolver"]


class VTypeResolver:
    """vType id → (mass [kg], applicability per equation, accounted?) for the loop.

    Mass: scenario ``vtypes.<id>.mass_kg`` > param ``drvpw.mass`` > ``mass`` attribute
    written in the route/additional files; none of them → UserError (see
    :mod:`sumo_drvpw.sim.vtypes` for why SUMO's own default is not accepted).
    Equations: scenario ``vtypes.<id>.equations`` > param ``drvpw.equation`` > all.
    """

    def __init__(self, scenario, file_vtypes: dict, names: list[str], conn=None):
        self.sc, self.files, self.names, self.conn = scenario, file_vtypes, names, conn
        self.cache: dict[str, tuple] = {}

    def _param(self, vt: str, key: str) -> str:
        if self.conn is None:
            return ""
        try:
            return self.conn.vehicletype.getParameter(vt, key) or ""
        except Exception:
            return ""

    def __call__(self, vt: str, vid: str):
        if vt in self.cache:
            return self.cache[vt]
        sc = self.sc
        keep = sc.vtype_filter is None or vt in sc.vtype_filter
        data = sc.vtype_data.get(vt, {})
        info = self.files.get(vt)
        mass = data.get("mass_kg")
        if mass is None and info is not None:
            mass = info.mass_kg
        if mass is None:
            p = self._param(vt, "drvpw.mass")
            if p:
                try:
                    mass = float(p)
                except ValueError:
                    raise UserError(f"vType '{vt}': drvpw.mass is not a number: {p!r}") from None
        eq = data.get("equations")
        if eq is None:
            one = (info.equation if info is not None else None) or self._param(vt, "drvpw.equation")
            eq = [one] if one else list(self.names)
        app = np.array([1.0 if n in eq else 0.0 for n in self.names])
        if keep and mass is None:
            where = f" (defined in {info.source})" if info is not None else \
                " (not defined in the route/additional files: SUMO's default type?)"
            raise UserError(
                f"vType '{vt}' of vehicle '{vid}'{where} has no mass: give it a mass attribute, "
                f'a <param key="drvpw.mass" value="..."/>, or vtypes.{vt}.mass_kg in the '
                "scenario (or leave it out with vehicles.vtypes)")
        out = (float(mass) if mass is not None else np.nan, app, keep)
        self.cache[vt] = out
        return out


#: How a step is booked (summary.json ``energy_booking``; docs/scenario.md).
ENERGY_BOOKING = ("acc term: coefficient × m·v̄·a with v̄ = (v_t + v_t−1)/2, i.e. the "
                  "kinetic-energy change ½m(v_t² − v_t−1²)/Δt, conserved at any step length; "
                  "other terms at the speed of the distance SUMO moved the car in the step "
                  "(Euler update: v_t; ballistic: v̄)")


def network_info(net, ledger, top: int = 10) -> dict:
    """The ``network`` block of summary.json: file, elevation, most-clipped lanes."""
    counts = ledger.lane_clipped
    order = np.argsort(-counts, kind="stable")[:top] if len(counts) else []
    lanes = {net.lane_ids[i]: int(counts[i]) for i in order if counts[i] > 0} \
        if net.lane_ids is not None else {}
    return {"file": str(net.path), "has_elevation": bool(net.has_elevation),
            "z_share": float(net.z_share), "slope_clipped_lanes": lanes}


def network_warnings(net) -> list[str]:
    """Warnings about the network a user should see (printed by the CLI)."""
    if net.has_elevation:
        return []
    return [f"network {net.path.name} has no elevation (no z in any lane shape): every slope "
            "is 0, so the grade term is 0; build it with elevation (netconvert "
            "--heightmap.geotiffs / OSM ele) for hilly areas"]


def _sumo_env() -> None:
    if not os.environ.get("SUMO_HOME"):
        try:
            import sumo

            os.environ["SUMO_HOME"] = sumo.SUMO_HOME
        except ImportError:
            pass


def start_sumo(args: list[str], connection: str = "libsumo", gui: bool = False,
               label: str = "drvpw"):
    """Start SUMO with command-line ``args``; returns the connection. UserError on failure."""
    import sumolib

    _sumo_env()
    binary = sumolib.checkBinary("sumo-gui" if gui else "sumo")
    cmd = [binary, *args, "--no-step-log", "true"]
    if connection == "libsumo":
        if gui:
            raise UserError("sumo.gui needs connection = 'traci'")
        import libsumo

        try:
            libsumo.start(cmd)
        except Exception as e:  # libsumo.TraCIException / FatalTraCIError
            try:
                libsumo.close()
            except Exception:
                pass
            raise UserError(f"SUMO failed to start ({' '.join(args)}): {e}") from None
        return libsumo
    import traci

    try:
        traci.start(cmd, label=label, stdout=open(os.devnull, "w"))
    except Exception as e:  # traci.exceptions.FatalTraCIError, OSError
        raise UserError(f"SUMO failed to start ({' '.join(args)}): {e}") from None
    return traci.getConnection(label)


def close_sumo(conn) -> None:
    """Close a connection, ignoring errors of an already closed one."""
    try:
        conn.close()
    except Exception:
        pass


def run_scenario(scenario_path, out_dir, **overrides) -> dict:
    """Run a scenario and write its outputs; returns the summary (also in summary.json).

    Parameters
    ----------
    scenario_path : scenario TOML file
    out_dir : output directory (created)
    overrides : replace scenario values: begin, end, step_length [s], connection, gui,
        options, equations (names, paths or Equation objects), trace, edgedata, figures,
        progress, difference
    """
    from sumo_drvpw.sim.ledger import EquationSet, Ledger
    from sumo_drvpw.sim.loop import Physics, run_loop
    from sumo_drvpw.sim.network import load_network
    from sumo_drvpw.sim.outputs import TraceWriter, summary_dict, write_outputs
    from sumo_drvpw.sim.scenario import load_scenario
    from sumo_drvpw.sim.vtypes import read_vtypes

    sc = load_scenario(scenario_path, **overrides)
    file_vtypes = read_vtypes(sc.route_files)
    equations = list(sc.equations)
    names = [e.name for e in equations]
    for info in file_vtypes.values():  # vTypes naming an equation the scenario lacks
        if info.equation and info.equation not in names:
            if sc.vtype_filter is not None and info.id not in sc.vtype_filter:
                continue
            from sumo_drvpw.sim.scenario import resolve_equation

            eq = resolve_equation(info.equation, Path(info.source).parent,
                                  f"{info.source}: vType '{info.id}' drvpw.equation")
            if eq.name != info.equation:
                raise UserError(f"{info.source}: vType '{info.id}' names equation "
                                f"'{info.equation}', whose name is '{eq.name}'")
            equations.append(eq)
            names.append(eq.name)
    net = load_network(sc.net_file, sc.road_class, sc.slope_window, sc.slope_max)
    eqset = EquationSet(equations)
    ledger = Ledger(len(net.edge_ids), len(equations))
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    physics = Physics(wind_speed=sc.wind_speed, wind_from_deg=sc.wind_from_deg, rho=sc.rho,
                      slope_tol=sc.slope_tol, slope_reference=sc.slope_reference,
                      acceleration=sc.acceleration, heading=sc.wind_heading,
                      positions=sc.positions)
    t0 = time.perf_counter()
    conn = start_sumo(sc.sumo_args, sc.connection, sc.gui)
    trace = None
    try:
        begin = float(conn.simulation.getTime())
        resolver = VTypeResolver(sc, file_vtypes, names, conn)
        if sc.trace:
            trace = TraceWriter(out_dir / "trace.parquet", ledger, names, net.edge_ids)
        try:
            info = run_loop(conn, net, eqset, ledger, physics, resolver, end=sc.end,
                            progress=sc.progress, trace=trace,
                            use_subscriptions=(sc.connection == "traci"))
        except Exception as e:
            if type(e).__name__ in ("TraCIException", "FatalTraCIError"):
                raise UserError(f"SUMO failed during the run: {e}") from None
            raise
    finally:
        if trace is not None:
            trace.close()
        close_sumo(conn)
    wall = time.perf_counter() - t0
    extra = {"scenario": str(sc.path) if sc.path else None, "begin_s": begin,
             "end_s": info["end_time_s"], "step_length_s": info["step_length_s"],
             "step_method": info["step_method"],
             "energy_booking": ENERGY_BOOKING,
             "network": network_info(net, ledger),
             "interrupted": info["interrupted"], "wall_time_s": wall,
             "connection": sc.connection, "air_density_kgm3": sc.rho,
             "slope_reference": sc.slope_reference, "acceleration_source": sc.acceleration,
             "position_source": sc.positions,
             "wind": {"speed_mps": sc.wind_speed, "from_deg": sc.wind_from_deg,
                      "heading_source": sc.wind_heading},
             "equation_sources": {e.name: (e.path or "<object>") for e in equations}}
    if sc.trace:
        extra["files"] = {"trace": "trace.parquet"}
    extra["warnings"] = network_warnings(net)
    summary = summary_dict(ledger, net, names, eqset.uses_other, extra)
    write_outputs(out_dir, ledger, net, names, summary, begin, info["end_time_s"],
                  sc.edgedata, sc.figures, sc.difference)
    return summary
