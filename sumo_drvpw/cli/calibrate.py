"""`sumo-drvpw calibrate`: stepwise-calibrate a DrvPw equation and report against VSP."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from sumo_drvpw.cli import add_force, add_log_options, existing_paths, note_counts, output_set, read_options
from sumo_drvpw.cli._fix import add_fix_argument, fix_option
from sumo_drvpw.cli._scale import add_engine_arguments, chain_input_note, replace_chain
from sumo_drvpw.errors import UserError


def configure(p):
    p.add_argument("logs", nargs="+", metavar="LOG", help="drive logs (Parquet/CSV files or folders)")
    p.add_argument("--vehicle", help="vehicle name or TOML file (optional when the log has power_w and mass_kg)")
    p.add_argument("--candidates", default="indt-var-1",
                   help="candidate terms: indt-var-1, indt-var-2, a TOML file with terms = [...], "
                        "or a comma list (default indt-var-1)")
    p.add_argument("--out", required=True, metavar="EQUATION.toml", help="calibrated equation file")
    p.add_argument("--name", help="equation name (default: the output file's stem)")
    p.add_argument("--report", metavar="DIR", help="also write the comparison report here "
                   "(the folder is written whole, or not at all)")
    add_force(p)
    add_log_options(p)
    p.add_argument("--compare-with", action="append", metavar="EQ",
                   help="equations for the report (default: vsp_ldv1999 and VSP from the vehicle's specs)")
    p.add_argument("--p-enter", type=float, default=0.10, help="p-value to enter (default 0.10)")
    p.add_argument("--p-remove", type=float, default=0.15, help="p-value to remove (default 0.15)")
    add_engine_arguments(p)
    g = p.add_argument_group("energy chain (battery or fuel; docs/energy-chain.md)")
    g.add_argument("--target", choices=("wheel", "battery", "fuel"), default="wheel",
                   help="what to calibrate on: driving power (default), battery V·I, or fuel flow; "
                        "battery/fuel fit the energy chain on top of the road-load equation")
    g.add_argument("--equation", metavar="NAME|FILE",
                   help="road-load equation under the chain: a name, a TOML file, or 'roadload_spec' "
                        "(the vehicle's published road load A + B·v + C·v², e.g. a dynamometer's) "
                        "(default: calibrate one stepwise on the log's measured driving power first)")
    g.add_argument("--load", action="append", default=[], metavar="COLUMN",
                   help="logged auxiliary load in W (e.g. heater_power_w); repeat")
    g.add_argument("--hvac", metavar="COLUMN[:SETPOINT_C]",
                   help="battery target: fit heating and cooling power per K of COLUMN (ambient °C) from "
                        "the set-point (default 20)")
    g.add_argument("--engine-off", metavar="never|W", dest="engine_off",
                   help="fuel chain: the engine never stops ('never': a conventional engine without "
                        "start-stop), or stops below this driving power in W (default: profiled from "
                        "the log, and 'never' where it idles at stops)")
    g.add_argument("--engine-max", choices=("declared", "profile"), default="declared", dest="engine_max",
                   help="fuel chain: the engine's rated output (engine_max_w): 'declared' (default: kept where "
                        "the --equation file's chain declares one, else none) or 'profile' (profiled on the "
                        "fit's residuals, kept only where its BIC beats the line without; fitted in memory)")
    g.add_argument("--fit-window", type=float, metavar="SECONDS", dest="fit_window",
                   help="fuel chain: fit the Willans line on means over windows of SECONDS within the trips "
                        "(e.g. 30), not on the samples: noise in a 1-Hz driving power (an acceleration derived "
                        "from speed, times the mass) flattens a per-sample line; use it where calibrate flags "
                        "the marginal efficiency ATTENUATED (fitted in memory)")
    g.add_argument("--efficiency", choices=("constant", "power", "speed-power"), default="constant",
                   help="battery chain: traction and recuperation efficiency as constants (default) "
                        "or tables over |power| (and speed), fitted on a piecewise-linear basis")
    add_fix_argument(g)


def _check_name(args) -> None:
    """The equation's name (``--name``, else the output file's stem) as an equation file
    allows it: refused before any work, not by the next command that reads the file."""
    import re

    from sumo_drvpw.model.equations import NAME_PATTERN

    if not str(args.candidates).strip(" ,"):  # before the paths: '' would read as the folder '.'
        raise UserError(f"--candidates {args.candidates!r}: give a set (indt-var-1, indt-var-2), a TOML "
                        "file or a comma list of terms")
    name = args.name if args.name is not None else Path(args.out).stem
    if not re.match(NAME_PATTERN, name):
        raise UserError(f"{'--name' if args.name is not None else '--out'} {name!r}: an equation name "
                        "is a letter, then letters, digits, '_', '.', '-' (at most 64 characters)")


def main(args) -> int:
    from sumo_drvpw.cli._scale import check_engine_arguments

    _check_name(args)
    check_engine_arguments(args)  # --workers, --scheduler only with --engine dask (every path)
    if getattr(args, "target", "wheel") != "wheel":
        return main_chain(args)
    if getattr(args, "equation", None) or getattr(args, "load", None) or getattr(args, "hvac", None):
        raise UserError("--equation, --load and --hvac go with --target battery or fuel")
    if getattr(args, "efficiency", "constant") != "constant":
        raise UserError(f"--efficiency {args.efficiency} goes with --target battery")
    fix_option(args, None)  # (refused: a battery chain's)
    from sumo_drvpw.fileio import _is_within, check_output_path

    for opt in ("p_enter", "p_remove"):
        val = getattr(args, opt)
        if not 0 < val < 1:
            raise UserError(f"--{opt.replace('_', '-')} must be between 0 and 1, got {val}")
    if args.p_enter > args.p_remove:
        raise UserError(f"--p-enter ({args.p_enter}) must not exceed --p-remove ({args.p_remove}), "
                        "or selection can cycle")
    out = Path(args.out)
    if out.suffix != ".toml":
        raise UserError(f"--out {out}: an equation file ends in .toml")
    inputs = existing_paths(args.logs, args.vehicle, args.candidates, args.compare_with)
    check_output_path(out, inputs, "file")
    if args.report:
        check_output_path(args.report, inputs, "folder")
        if _is_within(out.resolve(), Path(args.report).resolve()):
            raise UserError(f"--out {out} lies inside --report {args.report}, which is replaced "
                            "whole; write the equation elsewhere")
    from sumo_drvpw.fit.calibrate import calibrate, resolve_candidates  # (scipy, pandas: after the options' checks)
    from sumo_drvpw.data.measured import load_measured

    cands = resolve_candidates(args.candidates)
    if getattr(args, "engine", "memory") != "memory":  # streamed, bounded memory (issue #14)
        from sumo_drvpw.cli._scale import calibrate_streamed

        return calibrate_streamed(args, cands, out, inputs)
    m = load_measured(args.logs, args.vehicle, read_options(args))
    note_counts(m.counts)
    say_battery_power(m.source)
    check_speed_varies(m, cands)
    ref_mass = float(m.inputs.mass[m.usable].mean())
    res = calibrate(m.inputs, m.power_w, cands, mask=m.usable, p_enter=args.p_enter,
                    p_remove=args.p_remove, counts=m.counts, reference_mass_kg=ref_mass)
    check_identified(res, m.log.describe())
    name = args.name or out.stem
    from sumo_drvpw.data.powertrain import terms_predict_of
    from sumo_drvpw.data.trips import signature_texts, trip_signatures

    eq = res.to_equation(name, provenance={
        "logs": m.log.files, "vehicle": m.vehicle.path if m.vehicle else None,
        "power_source": m.source, "candidates_spec": args.candidates,
        "trip_signatures": signature_texts(trip_signatures(m.log.df))})
    eq.terms_predict = terms_predict_of(m.source)  # (the P_PTdrv of a power-split: its output)
    print(res.summary(physics=False))  # (the physics: physical() says, below)
    eq, _ = physical(eq, m, args.candidates)
    declare_measurement(eq, m.log.options.measurement)
    write_equation(args, eq, out, inputs, lambda tmp: write_calibration_report(m, eq, res, tmp, args.compare_with),
                   ref_mass)
    return 0


def log_columns(paths) -> set[str]:
    """Column names of the logs (their headers only; one that cannot be read here was read,
    or refused, by the reader)."""
    from sumo_drvpw.data.log_files import expand_paths
    from sumo_drvpw.data.stream import column_names

    return {c for p in expand_paths(paths) for c in column_names(p) or ()}


def physical(eq, m, candidates):
    """The equation, physically constrained where its free fit is implausible (issue #11 §3),
    and the note saying so ('' when plausible); the note and its hints are printed."""
    from sumo_drvpw.errors import UserError
    import numpy as np

    from sumo_drvpw.fit.physical import apply_physics, constraints_of

    try:
        eq, note = apply_physics(eq, m.inputs, m.power_w, m.usable, constraints_of(candidates))
    except UserError as e:  # about the data: name them
        raise UserError(f"{m.log.describe()}: {e}") from None
    if note:
        print(note)
        hint_grade_source(note, m.log.df.columns, m.log.options.measurement)
    rho = np.asarray(m.inputs.rho, float)[np.asarray(m.usable, bool)]
    say_physics(eq, m.vehicle, float(np.nanmean(rho)) if rho.size else None)
    return eq, note


def say_physics(eq, vehicle, rho_kgm3) -> None:
    """Print a warning when the written aero coefficient is no drag of the vehicle
    (:func:`sumo_drvpw.fit.vehicle_checks.drag_against_vehicle`, and the roll: `roll_against_vehicle`), and the grade at the wheels
    where the equation shows its drivetrain's η (:mod:`sumo_drvpw.fit.drivetrain`; a
    warning when it disagrees with the grade)."""
    from sumo_drvpw.fit.drivetrain import describe
    from sumo_drvpw.fit.vehicle_checks import drag_against_vehicle, roll_against_vehicle
    from sumo_drvpw.model.constants import RHO_DEFAULT

    phys = eq.provenance.get("physical", {})
    if phys.get("used") == "constrained":  # what is written, not the free fit printed above
        say_constrained(eq, phys)
    for note in (drag_against_vehicle(eq, vehicle, rho_kgm3 if rho_kgm3 and rho_kgm3 > 0 else RHO_DEFAULT),
                 roll_against_vehicle(eq, vehicle)):
        if note:
            print(f"warning: {note}")
    w = (phys.get("reading", {}).get("grade") or {}).get("at_wheels")
    if w:
        if "grade" in phys.get("active", ()):  # the constraints set it, not the data
            print(f"grade {describe(dict(w, plausible=True))} — the grade is held at its constraint, "
                  "so this reads only η")
        else:
            print(("" if w["plausible"] else "warning: ") + f"grade {describe(w)}")


def say_constrained(eq, phys) -> None:
    """Print the constrained fit the equation file gets (the table above is the free fit's)
    and its R²; a warning when that explains less than the power's mean does."""
    r2, free = eq.metrics.get("r2"), eq.metrics.get("r2_unconstrained")
    active = set(phys.get("active", ()))
    terms = ", ".join(f"{t} {c:.4g}" + (" (at its bound)" if t in active else "") for t, c in eq.terms.items())
    fit = "" if r2 is None else f"R² = {r2:.4f}" + ("" if free is None else f" (free fit {free:.4f})") + "; "
    print(f"written, physically constrained: {fit}{terms}")
    still = {t: r for t, r in phys.get("reading", {}).items() if r.get("plausible") is False}
    if still:  # a bound the constraints do not set (acc and roll have none above)
        print("warning: implausible as written, beyond what the constraints bound: "
              + "; ".join(f"{t} = {eq.terms[t]:.4g} ({r['note']})" for t, r in still.items()))
    if r2 is not None and r2 < 0:
        print(f"warning: the constrained equation explains less of the measured power than its mean does "
              f"(R² {r2:.3f}): the physics do not fit these data — check what the power column measures "
              "(its sign and unit, whether it logs traction only), the speed and the grade before using it")


def hint_grade_source(note: str, columns, meas) -> None:
    """When the grade was found attenuated and the log has a longitudinal accelerometer, or
    the acc coefficient below 1 (a lag), say how to correct the data instead of constraining
    the coefficient."""
    from sumo_drvpw.data.corrections import accelerometer_column

    col = accelerometer_column(columns)
    if "grade" in note and col and (meas is None or meas.grade == "logged"):
        print(f"hint: the log has a longitudinal accelerometer ({col}); --grade-source fused:300 corrects "
              "the grade in the data (diagnose says whether the accelerometer's grade fits better)")
    if "acc = " in note and "lag" in note and (meas is None or meas.power_lag_s == 0.0):
        print("hint: an acc coefficient below 1 is often a lag between the power and the speed signal; "
              "diagnose measures it (its timing finding, in seconds) and --power-lag S corrects it in the data")


def declare_measurement(eq, meas) -> None:
    """Write the corrections the logs were read with into the equation (``[measurement]``),
    so that comparisons on new logs read them the same way; say so. Logs read as they are
    leave none, whatever the --equation a chain was fitted on declared."""
    if meas is not None and not meas.identity:
        eq.measurement = meas
        print(f"measurement corrections (kept in the equation's [measurement]): {meas.describe()}")
    elif eq.measurement is not None and not eq.measurement.identity:
        eq.measurement = None
        print("measurement corrections: none, the logs as read (the road-load equation's [measurement] is not kept)")


#: speeds above this count as moving for the identifiability check [m/s]
MOVING_MPS = 0.5
#: power of v in the flat-road, still-air column of the speed-only terms (others: not checked)
SPEED_POWER = {"aero": 3, "aero_rho": 3, "v3": 3, "roll_v2": 2, "v2": 2, "roll": 1, "v1": 1}


def check_speed_varies(m, cands) -> None:
    """Refuse a log whose usable samples hold fewer than two distinct moving speeds: no term
    of ``cands`` can be identified on it (the stepwise road load of ``calibrate`` and of
    ``calibrate --target battery|fuel`` alike)."""
    moving = np.unique(np.round(m.inputs.v[m.usable & (m.inputs.v > MOVING_MPS)], 1))
    if len(moving) < 2:
        raise UserError(f"{m.log.describe()}: speed takes {len(moving)} distinct value(s) above "
                        f"{MOVING_MPS:g} m/s on the usable samples; {', '.join(cands)} cannot be "
                        "identified (they need the speed to vary); calibrate on a log with varying speed")


def check_identified(res, where: str) -> None:
    """Refuse a calibration whose data cannot tell its candidate terms apart.

    Two collapses mean the log is unfit, not that the model lacks a term: ``acc`` (m·v·a)
    zero on the data (speed never changes), or fewer distinct powers of v among the kept
    speed-only terms (aero ~ v³, roll ~ v, …) than among the candidates (too few distinct
    speeds: v³ becomes proportional to v). A column identical to another by physics on these
    data (``v3`` = ``aero`` without wind) is dropped quietly, as stepwise reports.
    """
    dropped = {d["term"]: d["reason"] for d in res.dropped}
    bad = [t for t, r in dropped.items() if t == "acc" and r.startswith("zero")]
    offered = {SPEED_POWER[t] for t in list(res.settings.get("candidates", [])) + list(dropped)
               if t in SPEED_POWER}
    kept = {SPEED_POWER[t] for t in res.settings.get("candidates", []) if t in SPEED_POWER and t not in dropped}
    if len(kept) < len(offered):
        bad += [t for t in dropped if t in SPEED_POWER and SPEED_POWER[t] not in kept]
    if bad:
        raise UserError(f"{where}: {', '.join(f'{t} ({dropped[t]})' for t in bad)}: these terms cannot "
                        "be identified because the speed takes too few distinct values; calibrate on "
                        "a log with varying speed")


#: the [body] values VSP from a vehicle's specs needs (model.equations.vsp_from_specs)
SPEC_KEYS = ("drag_coefficient", "frontal_area_m2", "rolling_coefficient")


def report_specs(vehicle, compare_with=None) -> tuple[list[str], str | None]:
    """The equations a calibration report compares with (``--compare-with``, else VSP LDV
    1999 and VSP from the vehicle's specs when its file gives them), and why the latter is
    left out when the file gives only some (None otherwise)."""
    if compare_with:
        return list(compare_with), None
    body = vehicle.body if vehicle is not None else None
    lacks = [k for k in SPEC_KEYS if k not in (body or {})]
    if body and not lacks:
        return ["vsp_ldv1999", "vsp_spec"], None
    return ["vsp_ldv1999"], (f"VSP from the vehicle's specs: {vehicle.path or vehicle.name} lacks "
                             + ", ".join(f"body.{k}" for k in lacks) if body else None)


def write_calibration_report(m, eq, res, out_dir, compare_with=None) -> dict:
    """Compare the calibrated equation with classic ones on the calibration samples."""
    from sumo_drvpw.fit.compare import compare
    from sumo_drvpw.report.comparison import write_comparison_report
    from sumo_drvpw.data.measured import resolve_equations

    specs, skipped = report_specs(m.vehicle, compare_with)
    eqs = [eq] + [e for e in resolve_equations(specs, m.vehicle) if e.name != eq.name]
    u = m.usable
    comp = compare(m.power_w[u], m.inputs.take(u), eqs, dt_s=m.log.df["dt_s"].to_numpy()[u],
                   reference=eq.name)
    ctx = m.context()
    if skipped:
        ctx["not compared"] = skipped
    ctx["calibration"] = {"equation": eq.name, "terms": eq.terms, "std_err": eq.std_err,
                          "p_values": eq.p_values, "r2": res.r2, "n": res.n,
                          "selection_trace": res.trace, "settings": res.settings,
                          "beta_mass_free": eq.metrics.get("beta_mass_free"),
                          "reference_mass_kg": res.reference_mass_kg,
                          "dropped_candidates": [f"{d['term']} dropped: {d['reason']}"
                                                 for d in res.dropped]}
    write_comparison_report(comp, out_dir, f"Calibration of {eq.name} against classic VSP", ctx)
    return comp.to_json()



def say_battery_power(source: str) -> None:
    """Warn when the driving power a road-load equation is fitted on is the battery's V·I
    (data/powertrain.POWER_SOURCES' last source: the logs hold no wheel or motor power)."""
    if "battery V·I" in str(source):
        print("warning: the measured driving power is the battery's V·I (the logs hold no wheel or motor "
              "power): the equation fitted on it books the drivetrain's losses and the auxiliary loads as "
              "road load — its coefficients are not the vehicle's, and a battery chain in a SUMO run would "
              "count the losses again; calibrate the chain on the battery instead (--target battery "
              "--equation roadload_spec, vsp_spec or a road load calibrated elsewhere)")


#: the heaviest vehicle an equation declaring the car classes is calibrated on without a
#: warning [kg]: 3.5 t, the EU's limit of a car or light van (categories M1/N1; trucks N2/N3
#: and buses M2/M3 above), the truck below: a rehearsal's 30-t diesel truck
CAR_MAX_MASS_KG = 3500.0


def say_vclasses(args, eq, out, log_mass_kg: float | None = None) -> None:
    """Warn when an equation calibrated on a vehicle heavier than :data:`CAR_MAX_MASS_KG`
    (the ``--vehicle`` file's mass, else ``log_mass_kg``, the log's own mean mass over the
    rows fitted: a log with a mass_kg column needs no vehicle file) declares no vClasses of its own: a SUMO run books it on
    the car classes, each car at its own mass (a truck's chain, 100 kW at zero output,
    booked 23.7 L/100 km for every car of the built-in highway)."""
    from sumo_drvpw.model.equations import DEFAULT_VCLASSES
    from sumo_drvpw.model.vehicles import load_vehicle

    if tuple(eq.vclasses) != DEFAULT_VCLASSES:
        return
    mass = float(load_vehicle(args.vehicle).mass_kg) if getattr(args, "vehicle", None) else log_mass_kg
    if mass is not None and mass > CAR_MAX_MASS_KG:
        print(f"warning: {eq.name} is calibrated on a {mass:,.0f}-kg vehicle but declares the car classes "
              f"({', '.join(DEFAULT_VCLASSES)}; no vclasses given): a SUMO run books it on every car at the "
              f"car's mass — write its class under [equation] in {out}, e.g. vclasses = [\"trailer\"] "
              "(or truck, bus, coach, delivery), or give it to its vTypes only (a scenario's "
              "vtypes.<id>.equations)")


def write_equation(args, eq, out, inputs, report=None, log_mass_kg: float | None = None) -> None:
    """The equation file, and with ``--report`` the report folder (``report(tmp)`` writes
    into it): both together, the equation written last, so neither is left without the other."""
    from sumo_drvpw.model.equations import save_equation

    say_vclasses(args, eq, out, log_mass_kg)

    if args.report:
        with output_set(args, args.report, inputs) as tmp:
            report(tmp)
            save_equation(eq, out)
        print(f"wrote {Path(args.report) / 'report.md'}")
    else:
        save_equation(eq, out)
    print(f"wrote {out}")


def engine_off_option(args) -> "str | float":
    """``--engine-off`` as the fuel chain takes it: "profile" (not given), −inf ('never') or
    a driving power [W]; refused in one line where it is not one or goes with another target."""
    val = getattr(args, "engine_off", None)
    if val is None or val == "profile":
        return "profile"
    if args.target != "fuel":
        raise UserError(f"--engine-off {val} goes with --target fuel (an engine's stops)")
    if str(val).strip().lower() == "never":
        return -math.inf
    try:
        w = float(val)
    except ValueError:
        w = math.nan
    if not math.isfinite(w) or w < 0:
        raise UserError(f"--engine-off {val}: give 'never' or the driving power in W below which the "
                        "engine stops (≥ 0, e.g. 0)")
    return w


def main_chain(args) -> int:
    """``calibrate --target battery|fuel``: the energy chain on top of a road-load equation.

    With constant efficiencies and ``--engine local`` (the default) or ``dask`` the logs are
    streamed (:func:`sumo_drvpw.cli._scale.calibrate_chain_streamed`, the same equation to
    1e-9 relative). With ``--engine memory`` or an efficiency table the logs are read once
    for the target and the driving power
    (:func:`~sumo_drvpw.data.measured.load_measured_pair`); once the road load is known, only
    the arrays the chain fit and its report need are kept and the table goes
    (:func:`~sumo_drvpw.data.measured.keep_arrays`)."""
    from sumo_drvpw.data.measured import keep_arrays, load_measured_pair, resolve_equations
    from sumo_drvpw.fileio import check_output_path
    from sumo_drvpw.fit.chain import calibrate_on
    from sumo_drvpw.fit.chain_checks import check_load_columns, check_one_driving_power
    from sumo_drvpw.fit.compare import compare

    out = Path(args.out)
    if out.suffix != ".toml":
        raise UserError(f"--out {out}: an equation file ends in .toml")
    efficiency = getattr(args, "efficiency", "constant")
    if efficiency != "constant" and args.target != "battery":
        raise UserError(f"--efficiency {efficiency} goes with --target battery (a fuel chain's "
                        "efficiency is its Willans line)")
    args.engine_off = engine_off_option(args)
    rating = getattr(args, "engine_max", "declared")
    if rating != "declared" and args.target != "fuel":
        raise UserError(f"--engine-max {rating} goes with --target fuel (an engine's rated output)")
    window = getattr(args, "fit_window", None)
    if window is not None and (args.target != "fuel" or not window > 0 or not np.isfinite(window)):
        raise UserError(f"--fit-window {window:g}: " + ("a positive number of seconds (e.g. 30)" if args.target == "fuel"
                        else "goes with --target fuel (a fuel chain's Willans line on windowed means)"))
    if window is not None and rating == "profile":  # a cap profiled on means that mix capped and uncapped driving
        raise UserError(f"--fit-window {window:g} with --engine-max profile: a rated output profiled on windowed "
                        "means reads low (a 300-kW engine read 191–299 kW on 60- to 10-s windows); profile it per "
                        "sample (--engine-max profile alone), write it into the equation's [chain] engine_max_w "
                        "and fit the windows with --engine-max declared")
    inputs = existing_paths(args.logs, args.vehicle, args.equation)
    check_output_path(out, inputs, "file")
    from sumo_drvpw.fit.chain_checks import not_a_power

    for c in args.load:
        if not_a_power(c):
            raise UserError(f"--load {c}: {not_a_power(c)}")
    hvac = None
    if args.hvac and args.target == "fuel":
        raise UserError(f"--hvac {args.hvac}: the HVAC power per kelvin is fitted for --target battery only; "
                        "a fuel chain books the climate's draw as auxiliary power (or a logged load, --load)")
    if args.hvac:
        col, _, sp = args.hvac.partition(":")
        try:
            hvac = {"column": col, "setpoint_c": float(sp) if sp else 20.0}
        except ValueError:
            raise UserError(f"--hvac {args.hvac}: the set-point after ':' must be a number (°C)") from None
        if not col or not -60.0 <= hvac["setpoint_c"] <= 60.0:
            raise UserError(f"--hvac {args.hvac}: give COLUMN[:SETPOINT_C] with a cabin set-point in "
                            "-60 … 60 °C")
    args.fix_values = fix_option(args, hvac)  # held at known values (in memory and streamed)
    engine = getattr(args, "engine", "memory")
    if window is not None and engine != "memory":  # (the streamed fit refuses the windowed fit; fitted in memory)
        if engine == "dask":
            raise UserError("--engine dask: --fit-window is fitted in memory (its windows are read within whole "
                            "trips of one table): leave --engine out")
        print("note: --fit-window is fitted in memory (its windows within whole trips); without it the fit is streamed")
    elif engine != "memory" and efficiency == "constant" and rating == "declared":  # streamed, bounded memory
        from sumo_drvpw.cli._scale import calibrate_chain_streamed

        return calibrate_chain_streamed(args, out, inputs, hvac)
    if engine == "dask" and window is None:
        raise UserError(f"--engine dask with --target {args.target} fits constant efficiencies only "
                        f"(--efficiency {efficiency} is fitted in memory): leave --engine out" if rating == "declared" else
                        "--engine dask: --engine-max profile is fitted in memory (its search reads the "
                        "logs once per cap tried): leave --engine out")
    if engine == "local" and window is None:
        print(f"note: --efficiency {efficiency} is fitted in memory (the tables' knots are quantiles of "
              "the driving power); only constant efficiencies are streamed" if rating == "declared" else
              "note: --engine-max profile is fitted in memory (its search reads the logs once per cap "
              "tried); a declared rated output is streamed")
    ro = read_options(args, [args.equation] if args.equation else ())
    m, mw = load_measured_pair(args.logs, args.vehicle, ro, args.target)
    note_counts(m.counts)
    log_mass = float(np.mean(m.inputs.mass[m.usable])) if m.usable.any() else None  # (say_vclasses)
    from sumo_drvpw.data.trips import signature_texts, trip_signatures

    trips = signature_texts(trip_signatures(m.log.df))  # (the table is dropped before the chain's fit)
    check_load_columns(m, args.load)  # before the road-load fit
    if hvac and hvac["column"] not in m.inputs.signals:
        raise UserError(f"--hvac {args.hvac}: {m.log.describe()} has no column '{hvac['column']}' "
                        f"(extra columns: {', '.join(sorted(m.inputs.signals)) or 'none'})")
    check_one_driving_power(m.log.files)  # else a file's rows without it drop out silently
    if args.equation:
        eq = resolve_equations([args.equation], m.vehicle, predicting=False)[0]
        road = f"road-load equation {eq.name} ({eq.path or 'built in'})"
    else:
        from sumo_drvpw.fit.calibrate import calibrate, resolve_candidates

        if isinstance(mw, UserError):
            raise mw
        if mw.source.startswith("battery"):  # the road load would be fitted on the chain's own target
            raise UserError(f"--target {args.target}: {mw.log.describe()} logs no driving power (power_w, motor "
                            "torque, the power-split signals), only battery V·I, so the road load cannot be "
                            "told apart from the chain's losses; give its road load with --equation (e.g. "
                            "roadload_spec, the vehicle's published A + B·v + C·v², or an equation calibrated "
                            "on logs with a driving power)")
        from sumo_drvpw.data.measured import with_signals
        from sumo_drvpw.model.terms import parse_term

        cands = resolve_candidates(args.candidates)  # the columns its terms read, as arrays
        mw = with_signals(mw, {c for t in cands for c in parse_term(t).columns})
        check_speed_varies(mw, cands)  # as plain `calibrate`: the road load needs varying speed
        res = calibrate(mw.inputs, mw.power_w, cands, mask=mw.usable,
                        p_enter=args.p_enter, p_remove=args.p_remove, counts=mw.counts,
                        reference_mass_kg=float(mw.inputs.mass[mw.usable].mean()))
        check_identified(res, mw.log.describe())
        eq = res.to_equation(args.name or out.stem, provenance={
            "logs": mw.log.files, "power_source": mw.source, "candidates_spec": args.candidates,
            "trip_signatures": trips})
        print(res.summary(physics=False))
        eq, note = physical(eq, mw, args.candidates)  # the same physics as `calibrate`
        road = f"road-load equation calibrated stepwise on {mw.source}" + (
            " (physically constrained: the free fit was implausible)" if note else "")
    # the chain's input: the log's measured driving power when it has one (the chain then
    # describes the powertrain, not the road-load equation's errors), else the equation's
    p_in, chain_input = None, f"driving power of {eq.name}"
    if not isinstance(mw, UserError) and not mw.source.startswith("battery"):
        p_in, chain_input = np.array(mw.power_w, float), f"measured driving power ({mw.source})"
    mw_source = None if p_in is None else mw.source
    from sumo_drvpw.model.terms import parse_term

    keep = set(args.load) | ({hvac["column"]} if hvac else set())
    keep |= {c for t in eq.terms for c in parse_term(t).columns}
    m = keep_arrays(m, sorted(keep))  # the table goes with the last reference to it
    del mw
    fit = calibrate_on(m, eq, loads=args.load, hvac=hvac, p_drive_w=p_in, efficiency=efficiency,
                       engine_off=args.engine_off, rating=rating, window_s=window, fixed=args.fix_values)
    eq.name = args.name or out.stem
    replace_chain(eq, fit.chain)
    eq.chain.provenance = {**fit.chain.provenance, "logs": m.log.files, "target": m.source, "road_load": road,
                           "chain_input": chain_input,
                           "vehicle": m.vehicle.path if m.vehicle else None,
                           "trip_signatures": trips, **({"fixed": args.fix_values} if args.fix_values else {})}
    eq.chain.reading = {k: p.get("reading", "") for k, p in fit.parameters.items()}
    declare_measurement(eq, ro.measurement)
    if note := chain_input_note(args.equation, mw_source):
        print(note)
    print(fit.summary())
    for w in fit.warnings:  # implausible or unidentified parameters (fit/chain_checks.py)
        print(f"warning: {w}")

    def report(tmp):
        from sumo_drvpw.report.comparison import write_comparison_report

        u = m.usable
        comp = compare(m.power_w[u], m.inputs.take(u), [eq], dt_s=m.log.df["dt_s"].to_numpy()[u],
                       target=args.target,
                       battery_w=None if m.battery_w is None else m.battery_w[u])
        from sumo_drvpw.fit.trip_energy import left_out_by_trip  # partial trips, as compare says

        comp.left_out = left_out_by_trip(m.power_w, u, m.log.df["dt_s"].to_numpy(), m.inputs.trip)
        ctx = m.context()
        ctx["calibration"] = {"equation": eq.name, "chain": fit.parameters, "r2": fit.r2,
                              "n": fit.n, "road_load": road}
        write_comparison_report(comp, tmp, f"Energy chain of {eq.name} against measured "
                                f"{args.target} power", ctx)

    write_equation(args, eq, out, inputs, report, log_mass)
    return 0
