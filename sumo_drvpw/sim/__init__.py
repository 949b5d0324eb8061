"""SUMO plug-in: driving power and energy per term for every vehicle of a simulation.

``run_scenario(scenario_path, out_dir=None, **overrides) -> RunResult`` runs a scenario
file (:mod:`.scenario`) with libsumo (or traci) and writes the outputs of :mod:`.outputs`;
``Accountant`` does the same inside a user's own TraCI/libsumo loop (a step listener);
``process_fcd`` (:mod:`.fcd`; ``process_fcd_dask`` in :mod:`.fcd_dask`) books a finished run
from SUMO's FCD output. Modules, in the order the data travel: ``scenario`` (config),
``vtypes`` (mass, vClass and drvpw.* params from the route files), ``resolver`` (which
equations book a vType, at what mass), ``network`` (edge table, road classes, robust slopes),
``reader`` (a step's state from SUMO), ``loop`` (one step at a time, connection passed in),
``ledger`` (vectorized evaluation and accumulation), ``chain`` (battery and fuel accounts),
``accountant`` (ties them to a connection), ``outputs`` (tables, edgeData, figures,
RunResult); ``sumo_start`` starts SUMO, ``run`` runs a scenario; ``fcd*`` replay FCD files.
"""

__all__ = ["run_scenario", "start_sumo", "close_sumo", "VTypeResolver", "Accountant",
           "RunResult", "process_fcd"]

#: each name's module, imported on first use: importing one module of the package (a command's
#: option reading a SUMO time, sim/scenario_values.py) loads neither the loop nor pandas
_HOME = {"Accountant": "accountant", "RunResult": "outputs", "VTypeResolver": "run", "close_sumo": "run",
         "run_scenario": "run", "start_sumo": "run", "process_fcd": "fcd"}


def __getattr__(name):
    if name in _HOME:
        from importlib import import_module

        return getattr(import_module(f"sumo_drvpw.sim.{_HOME[name]}"), name)
    if not name.startswith("_"):  # a module of the package (sim.chain.ChainLedger), as before the lazy names
        from importlib import import_module, util

        if util.find_spec(f"sumo_drvpw.sim.{name}") is not None:
            return import_module(f"sumo_drvpw.sim.{name}")
    raise AttributeError(f"module 'sumo_drvpw.sim' has no attribute {name!r}")


def __dir__():  # (the lazy names too: help(), tab completion)
    return sorted({*globals(), *_HOME})
