"""Every built-in equation, plus each study's calibrated and physical ones, on every data set.

Built-in equations were calibrated or defined for other cars, so on most data sets this
is a cross-vehicle test, not a validation. Each data set is evaluated on its study's
``mask`` (held-out samples where the study has a split). The data sets are passenger
cars: built-ins made for other SUMO vehicle classes (buses, trucks, motorcycles: their
``vclasses``) are listed, not evaluated.
"""

from __future__ import annotations

import numpy as np

from sumo_drvpw.validation.data import compare_on, metrics_row

#: SUMO vehicle class of the validation data sets: built-ins made for it are evaluated.
VEHICLE_CLASS = "passenger"


def study(datasets: dict, results: dict) -> dict:
    """Metrics of every equation per data set.

    Parameters
    ----------
    datasets : data-set folder → :class:`sumo_drvpw.validation.data.Dataset`
    results : data-set folder → :class:`sumo_drvpw.validation.data.StudyResult`

    Returns data-set folder → ``{"n", "target", "mass_kg_mean", "equations": {NAME:
    metrics row + "fixed_mass_kg", "builtin"}, "other_class_builtins": [NAME, …],
    "in_sample_builtins": [NAME, …]}`` (built-ins fitted on the evaluated trips: not scored).
    """
    from sumo_drvpw.model.equations import builtin_names, load_equation

    out = {}
    names_builtin = builtin_names()
    loaded = [load_equation(n) for n in names_builtin]
    builtins = [e for e in loaded if VEHICLE_CLASS in e.vclasses]
    other_class = [e.name for e in loaded if VEHICLE_CLASS not in e.vclasses]
    for key, ds in datasets.items():
        mask = results[key].mask
        eqs = list(results[key].equations)
        own = {e.name for e in eqs}
        trips = set(np.unique(ds.trip[mask]))
        # a built-in fitted on these very trips (the i3 battery deliverable) would be scored
        # in sample here: listed, not scored
        in_sample = sorted(e.name for e in builtins
                           if trips & {str(t) for t in (e.provenance or {}).get("trips", [])})
        eqs += [e for e in builtins if e.name not in own and e.name not in in_sample]
        comp = compare_on(ds, mask, eqs)
        out[key] = {"n": int(mask.sum()), "target": ds.source,
                    "mass_kg_mean": float(ds.inputs.mass[mask].mean()),
                    "equations": {e.name: {**metrics_row(comp, e.name),
                                           "fixed_mass_kg": e.mass_kg,
                                           "builtin": e.name in names_builtin}
                                  for e in eqs},
                    "other_class_builtins": other_class, "in_sample_builtins": in_sample}
    return out
