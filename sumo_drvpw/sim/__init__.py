"""SUMO plug-in: driving power and energy per term for every vehicle of a simulation.

``run_scenario(scenario_path, out_dir, **overrides) -> summary`` runs a scenario file
(:mod:`.scenario`) with libsumo (or traci) and writes the outputs of :mod:`.outputs`.
Modules, in the order the data travel: ``scenario`` (config), ``vtypes`` (mass and
drvpw.* params from the route files), ``network`` (edge table, road classes, robust
slopes), ``loop`` (the stepping loop, connection passed in), ``ledger`` (vectorized
evaluation and accumulation), ``outputs``; ``run`` starts SUMO and ties them together.
"""

from sumo_drvpw.sim.run import VTypeResolver, close_sumo, run_scenario, start_sumo

__all__ = ["run_scenario", "start_sumo", "close_sumo", "VTypeResolver"]
