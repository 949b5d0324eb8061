"""SUMO plug-in: driving power and energy per term for every vehicle of a simulation.

``run_scenario(scenario_path, out_dir=None, **overrides) -> RunResult`` runs a scenario
file (:mod:`.scenario`) with libsumo (or traci) and writes the outputs of :mod:`.outputs`;
``Accountant`` does the same inside a user's own TraCI/libsumo loop (a step listener);
``process_fcd`` books a finished run from SUMO's FCD output. Modules, in the order the data
travel: ``scenario`` (config), ``vtypes`` (mass, vClass and drvpw.* params from the route
files), ``network`` (edge table, road classes, robust slopes), ``loop`` (one step at a
time, connection passed in), ``ledger`` (vectorized evaluation and accumulation),
``accountant`` (ties them to a connection), ``outputs`` (tables, edgeData, figures,
RunResult); ``run`` starts SUMO; ``fcd`` replays FCD files.
"""

from sumo_drvpw.sim.accountant import Accountant
from sumo_drvpw.sim.outputs import RunResult
from sumo_drvpw.sim.run import VTypeResolver, close_sumo, run_scenario, start_sumo

__all__ = ["run_scenario", "start_sumo", "close_sumo", "VTypeResolver", "Accountant",
           "RunResult"]
