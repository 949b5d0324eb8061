"""The measurement corrections a command reads its logs with: the ``[measurement]`` its
equations declare, with each correction flag given put over its own setting only
(``--speed-scale 0.98`` keeps the equation's power lag and air density). A flag switches its
setting off with its "none" value: ``--power-lag 0``, ``--grade-source logged``,
``--air-density logged``, ``--no-exclude-dropouts``, ``--speed-scale 1``. The note printed
says which setting came from where (:func:`sumo_drvpw.cli.add_log_options` adds these flags,
:func:`sumo_drvpw.cli.read_options` reads with them). Argparse and printing only; the merge is
:func:`sumo_drvpw.model.measurement.override_measurement`.
"""

from __future__ import annotations

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


def add_corrections(p) -> None:
    """The correction flags, each over its own setting of an equation's ``[measurement]``."""
    g = p.add_argument_group(
        "measurement corrections (default: none, or what the --equation files declare in [measurement]; "
        "each given here sets only its own setting over that)")
    g.add_argument("--power-lag", type=float, metavar="S",
                   help="the power signal's lag behind the speed signal [s] (diagnose's timing finding): "
                        "the power is read S later within each trip")
    g.add_argument("--grade-source", metavar="logged|fused[:LENGTHm|:TAU_Ss]|accelerometer[:OFFSET_MPS2]",
                   help="grade from the elevation (logged), fused with a longitudinal accelerometer "
                        "(accelerometer above the crossover, elevation below; in time, default 60s, or "
                        "over driven distance, e.g. :1000m, which keeps each trip's elevation change), or the "
                        "accelerometer alone: its per-trip offset fixed by the elevation change, or with "
                        ":OFFSET_MPS2 less the logger's own fixed offset (no elevation used)")
    g.add_argument("--air-density", choices=("logged", "altitude"),
                   help="altitude = pressure of the standard atmosphere at the logged elevation when "
                        "pressure is not logged (default: logged, i.e. sea level without pressure)")
    g.add_argument("--exclude-dropouts", action="store_true", default=None,
                   help="leave out logger dropouts: speed and a longitudinal accelerometer held or "
                        "linearly filled for seconds (inputs only)")
    g.add_argument("--speed-scale", metavar="gps|K",
                   help="the logged speed times K before acceleration, distance and grade are derived from it "
                        "(0.984: a speedometer 1.6%% high; 1: as logged), or gps: each trip's own K against the GPS speed "
                        "logged beside it (gps_speed…_mps, or gps:COLUMN; steady samples above 8 m/s). Never in SUMO")
    g.add_argument("--no-exclude-dropouts", dest="exclude_dropouts", action="store_false", default=None,
                   help="keep logger dropouts an equation's [measurement] leaves out")


def _flags_measurement(args):
    """The :class:`~sumo_drvpw.model.measurement.Measurement` of --power-lag, --grade-source,
    --air-density and --exclude-dropouts alone (each checked as its flag; None when none is given)."""
    from sumo_drvpw.model.measurement import GRADE_SOURCES, measurement_from_dict

    lag, grade, rho, drop = (getattr(args, k, None) for k in ("power_lag", "grade_source", "air_density",
                                                              "exclude_dropouts"))
    if lag is not None or grade is not None or rho is not None or drop:
        doc = {"exclude_dropouts": True} if drop else {}
        if lag is not None:
            doc["power_lag_s"] = lag
        if grade is not None:
            src, _, num = str(grade).partition(":")
            if src not in GRADE_SOURCES or (num and src == "logged"):
                raise UserError(f"--grade-source {grade}: use one of logged, fused[:LENGTHm|:TAU_Ss], "
                                "accelerometer[:OFFSET_MPS2]")
            doc["grade"] = src
            if num:
                key, what = (("fusion_tau_s", "the crossover after ':' must be a distance in metres "
                              "(e.g. 1000m) or a time in seconds (e.g. 60s; a bare number is seconds)")
                             if src == "fused" else
                             ("accelerometer_offset_mps2", "the offset after ':' must be a number in m/s²"))
                if src == "fused" and num.strip().lower().endswith("m"):
                    key, num = "fusion_distance_m", num.strip()[:-1]
                elif src == "fused" and num.strip().lower().endswith("s"):
                    num = num.strip()[:-1]
                try:
                    doc[key] = float(num)
                except ValueError:
                    raise UserError(f"--grade-source {grade}: {what}") from None
        if rho is not None:
            doc["air_density"] = rho
        for flag, val, keys in (("--power-lag", lag, ("power_lag_s",)), ("--grade-source", grade, GRADE_KEYS),
                                ("--air-density", rho, ("air_density",))):  # (an error names its flag)
            if val is not None:
                measurement_from_dict({k: doc[k] for k in keys if k in doc}, f"{flag} {val:g}" if isinstance(val, float)
                                      else f"{flag} {val}")
        try:
            return measurement_from_dict(doc, "command line")
        except UserError as e:
            raise UserError(f"--power-lag / --grade-source / --air-density: {e}") from None
    return None


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
    given = _given(args)
    if not given:
        return {}
    meas = _flags_measurement(args) if any(d != "speed_scale" for d in given) else None
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


def speed_scale_origin(args) -> str | None:
    """Where a command's speed scale was said, as the user wrote it: ``--speed-scale``, else the
    first ``--equation`` file whose ``[measurement]`` declares one ('EQ.toml [measurement]
    speed_scale'); None for neither (a library message naming the scale is then left as it is)."""
    if getattr(args, "speed_scale", None) is not None:
        return "--speed-scale"
    from sumo_drvpw.model.equations import SPEC_EQUATIONS, load_equation

    specs = getattr(args, "equation", None) or ()
    for spec in [specs] if isinstance(specs, str) else specs:
        if not isinstance(spec, str) or spec in SPEC_EQUATIONS:
            continue
        try:
            m = load_equation(spec).measurement
        except (UserError, OSError):
            continue
        if m is not None and m.speed_scale not in (None, 1.0):
            return f"{spec} [measurement] speed_scale"
    return None
