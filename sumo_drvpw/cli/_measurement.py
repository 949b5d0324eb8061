"""The measurement corrections a command reads its logs with: the ``[measurement]`` its
equations declare, with each correction flag given put over its own setting only
(``--speed-scale 0.98`` keeps the equation's power lag and air density). A flag switches its
setting off with its "none" value: ``--power-lag 0``, ``--grade-source logged``,
``--air-density logged``, ``--no-exclude-dropouts``, ``--speed-scale 1``. The note printed
says which setting came from where. Argparse and printing only; the merge is
:func:`sumo_drvpw.model.measurement.override_measurement`.
"""

from __future__ import annotations

import argparse
import dataclasses

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.measurement import GRADE_KEYS

#: each correction flag: its argparse dest, its name, the [measurement] settings it sets
FLAGS = (("power_lag", "--power-lag", ("power_lag_s",)),
         ("grade_source", "--grade-source", GRADE_KEYS),
         ("air_density", "--air-density", ("air_density",)),
         ("exclude_dropouts", "--exclude-dropouts", ("exclude_dropouts",)),
         ("speed_scale", "--speed-scale", ("speed_scale",)))
#: the flags' "none" values, as the note says them
OFF = "--power-lag 0, --grade-source logged, --air-density logged, --no-exclude-dropouts, --speed-scale 1"


def add_log_options(p) -> None:
    """:func:`sumo_drvpw.cli.add_log_options` and --no-exclude-dropouts, which switches off
    the dropouts an equation's [measurement] leaves out (the other flags have a "none" value)."""
    from sumo_drvpw import cli

    cli.add_log_options(p)
    group = next((g for g in p._action_groups if str(g.title).startswith("measurement corrections")), p)
    group.add_argument("--no-exclude-dropouts", dest="exclude_dropouts", action="store_false", default=None,
                       help="keep logger dropouts an equation's [measurement] leaves out")


def _given(args) -> list[str]:
    """The correction flags (dests) given on the command line."""
    return [d for d, _, _ in FLAGS if getattr(args, d, None) is not None]


def speed_scale_flag(scale) -> float | str:
    """--speed-scale as given: gps, gps:COLUMN or a number, checked."""
    from sumo_drvpw.model.measurement import speed_scale_value

    s = str(scale).strip()
    if s.lower() == "gps" or s.lower().startswith("gps:"):
        v = "gps" + s[3:]
    else:
        try:
            v = float(s)
        except ValueError:
            raise UserError(f"--speed-scale {scale}: give gps, gps:COLUMN (the GPS speed column to measure it "
                            "against) or a number (the factor on the logged speed)") from None
    return speed_scale_value(v, f"--speed-scale {scale}")


def given_settings(args) -> dict:
    """The ``[measurement]`` settings the correction flags given set (a partial table, each
    checked as the flag's own); {} when none is given."""
    from sumo_drvpw import cli

    given = _given(args)
    if not given:
        return {}
    # the flags' own parsing and messages (cli.measurement_options, on the flags alone)
    flags = argparse.Namespace(**{d: getattr(args, d, None) for d, _, _ in FLAGS if d != "speed_scale"},
                               speed_scale=None)
    meas = cli.measurement_options(flags) if any(d != "speed_scale" for d in given) else None
    doc = {} if meas is None else meas.to_dict()
    out = {k: doc[k] for d, _, keys in FLAGS if d in given and d != "speed_scale" for k in keys if k in doc}
    if "exclude_dropouts" in given:  # (--exclude-dropouts True, --no-exclude-dropouts False)
        out["exclude_dropouts"] = bool(args.exclude_dropouts)
    if "speed_scale" in given:
        out["speed_scale"] = speed_scale_flag(args.speed_scale)
    return out


def _settings_text(doc: dict) -> str:
    """Settings as the ``[measurement]`` table writes them: ``power_lag_s = 1.5, grade = "fused"``."""
    def value(v):
        return f'"{v}"' if isinstance(v, str) else str(v).lower() if isinstance(v, bool) else f"{v:g}"

    return ", ".join(f"{k} = {value(v)}" for k, v in doc.items())


def measurement_options(args, equations=(), say: bool = True):
    """The measurement corrections of a command (:class:`sumo_drvpw.model.measurement.Measurement`
    or None): the ``[measurement]`` the equation files among ``equations`` declare (all the
    same once the flags are put over them, or an error naming them), each correction flag given
    over its own setting; the flags' alone when no equation declares one. Prints (``say``) a
    note naming which setting came from the command line and which from the equations."""
    from sumo_drvpw.model.equations import SPEC_EQUATIONS, load_equation
    from sumo_drvpw.model.measurement import Measurement, measurement_from_dict, override_measurement

    given = given_settings(args)
    declared = {}
    for spec in equations or ():
        if not isinstance(spec, str) or spec in SPEC_EQUATIONS:
            continue
        eq = load_equation(spec)
        if eq.measurement is not None and not eq.measurement.identity:
            declared[spec] = eq.measurement
    if not declared:
        return measurement_from_dict(given, "command line") if given else None
    merged = {spec: override_measurement(m, given, f"{spec} with the command line's corrections")
              for spec, m in declared.items()}
    if len(set(merged.values())) > 1:
        docs = [m.to_dict() for m in merged.values()]
        differ = [f for _, f, keys in FLAGS if any(len({str(d.get(k)) for d in docs}) > 1 for k in keys)]
        raise UserError("--equation: the equations were calibrated on differently corrected logs "
                        f"({'; '.join(f'{k}: {v.describe()}' for k, v in declared.items())}); give "
                        f"{' and '.join(differ)} to choose")
    meas = next(iter(merged.values()))
    if say:
        default = Measurement().to_dict()
        kept = {k: v for m in declared.values() for k, v in m.to_dict().items()
                if k in meas.to_dict() and k not in given and not (k in default and default[k] == v)}
        where = ", ".join(declared)
        src = f"from the [measurement] of {where}: {_settings_text(kept) or 'nothing'}"
        if given:
            src = f"from the command line: {_settings_text(given)}; " + src
        print(f"note: logs corrected as the [measurement] of {where} declares"
              + (", the command line's settings over it" if given else "")
              + f": {meas.describe()} ({src}; a correction flag sets only its own setting, and {OFF} "
              "switch one off)")
    return meas


def read_options(args, equations=()):
    """:func:`sumo_drvpw.cli.read_options` with the measurement corrections of
    :func:`measurement_options` (each flag over its own setting of the equations')."""
    from sumo_drvpw import cli

    meas = measurement_options(args, equations)
    bare = argparse.Namespace(**{**vars(args), **{d: None for d, _, _ in FLAGS}})
    opt = cli.read_options(bare)  # the reading options' own checks: no correction, no equation
    if opt.flat_road and getattr(meas, "grade", "logged") != "logged":
        raise UserError(f"--flat-road sets the logs' grade aside, the grade source '{meas.grade}' "
                        "(--grade-source, or the equations' [measurement]) reads it: give one of them")
    return dataclasses.replace(opt, measurement=meas, fuel=cli.chains_fuel(equations))
