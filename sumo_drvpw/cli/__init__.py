"""Command line: parses arguments, loads files, calls library functions; no model logic.

Each sub-command lives in the module named in COMMANDS, which defines
``configure(parser)`` (add its arguments) and ``main(args) -> int``. A UserError
anywhere becomes a one-line message on stderr and exit code 2, without a traceback.
"""

from __future__ import annotations

import argparse
import errno
import importlib
import os
import signal
import sys
import warnings

from sumo_drvpw.cli._parser import _Parser
from sumo_drvpw.cli._signals import (_INTERRUPTED, _TERMINATED, _Terminated, _on_sigint, _on_sigterm,  # noqa: F401
                                      _quiet_signal_hook, _signal_exit, _stopped_by_signal)
from sumo_drvpw.errors import NoDrivingPower, OutputExists, UserError

#: sub-command → (module, one-line help)
COMMANDS = {
    "demo": ("sumo_drvpw.cli.demo", "synthesize, calibrate, compare and simulate on bundled data"),
    "synth": ("sumo_drvpw.cli.synth", "generate a synthetic Prius3-like 8 Hz test-track log"),
    "calibrate": ("sumo_drvpw.cli.calibrate", "stepwise-calibrate a DrvPw equation from logs"),
    "compare": ("sumo_drvpw.cli.compare", "compare equations against a log's measured power"),
    "run": ("sumo_drvpw.cli.run", "apply equations to every vehicle of a SUMO scenario"),
    "fcd": ("sumo_drvpw.cli.fcd", "apply equations to a finished SUMO run's FCD output"),
    "export-vtype": ("sumo_drvpw.cli.export_vtype",
                     "write a SUMO Energy-model vType from an equation (an MMPEVEM one when its chain "
                     "is SUMO's MMPEVEM motor)"),
    "import": ("sumo_drvpw.cli.import_", "convert vendor logs to canonical drive logs"),
    "validate": ("sumo_drvpw.cli.validate", "validation report on the real data in ../shared/data"),
    "diagnose": ("sumo_drvpw.cli.diagnose", "trace the residual of an equation to missing effects"),
    "dynamics": ("sumo_drvpw.cli.dynamics", "driving dynamics of drive logs, as a SUMO run reports its "
                 "trajectories' (EU RDE figures, accelerations by speed, a vType acceleration profile)"),
}


def build_parser(lazy: bool = False) -> argparse.ArgumentParser:
    """The command line's parser; ``lazy``: a command's module is imported (and its options
    added) only when it is the command given, so that ``--help`` and an option refused load no
    other command's imports (pandas: half a second)."""
    from sumo_drvpw import __version__

    parser = _Parser(prog="sumo-drvpw", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"sumo-drvpw {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser, action=_Commands)
    for name, (module, help_) in COMMANDS.items():
        p = sub.add_parser(name, help=help_, description=help_)
        if lazy:
            sub.pending[name] = module
        else:
            _configure(p, module)
    return parser


def _configure(p: argparse.ArgumentParser, module: str) -> None:
    """A command's options (its module's ``configure``) and ``main`` on its parser ``p``."""
    try:
        mod = importlib.import_module(module)
    except ModuleNotFoundError as e:
        if e.name and e.name.startswith("sumo_drvpw"):
            p.set_defaults(_missing=module)
            return
        raise
    mod.configure(p)
    p.set_defaults(_main=mod.main)


class _Commands(argparse._SubParsersAction):
    """The sub-commands; those in ``pending`` (command → module) are configured when given."""

    def __init__(self, *a, **kw):
        super().__init__(*a, **kw)
        self.pending: dict[str, str] = {}

    def __call__(self, parser, namespace, values, option_string=None):
        if values and values[0] in self.pending:
            _configure(self.choices[values[0]], self.pending.pop(values[0]))
        super().__call__(parser, namespace, values, option_string)


def sumo_time_arg(text: str) -> float:
    """argparse type of a SUMO time option: seconds or SUMO's h:m:s / d:h:m:s."""
    from sumo_drvpw.sim.scenario_values import sumo_seconds

    t = sumo_seconds(text)
    if t is None:
        raise argparse.ArgumentTypeError(f"not a time in seconds or h:m:s: {text!r}")
    return t


def add_force(p) -> None:
    """The ``--force`` option of a command that writes an output folder."""
    p.add_argument("--force", action="store_true",
                   help="replace an existing output folder even if sumo-drvpw did not write it")


def add_cold_start(p, during: str) -> None:
    """The ``--cold-start`` and ``--cold-start-share`` options of ``run`` and ``fcd``."""
    p.add_argument("--cold-start", action="store_true",
                   help=f"every vehicle departing {during} starts a cold engine: fuel chains add their "
                        "cold_start_fuel_l over its first minutes, as it decays from the departure "
                        "(the scenario's [vehicles] cold_start; default: trips start warm)")
    p.add_argument("--cold-start-share", type=float, metavar="SHARE",
                   help="only this share (0-1) of the departing vehicles starts cold: fuel chains add "
                        "that share of their cold start to each trip (a fleet's expected fuel); "
                        "a vType's or vClass's own cold_start in the scenario wins over either option")


def cold_start_override(args, overrides: dict) -> None:
    """Put the cold-start options into the scenario ``overrides`` (``cold_start``: a share)."""
    share = getattr(args, "cold_start_share", None)
    if share is not None and getattr(args, "cold_start", False) and share != 1.0:
        raise UserError(f"--cold-start (every trip starts cold) and --cold-start-share {share:g} say "
                        "different things: give one")
    if share is not None:
        if not 0.0 <= share <= 1.0:
            raise UserError(f"--cold-start-share {share:g}: a share of the vehicles, from 0 to 1")
        overrides["cold_start"] = share
    elif getattr(args, "cold_start", False):
        overrides["cold_start"] = 1.0


def check_air_temperature(t: float | None) -> None:
    """``--air-temperature`` (``run``, ``export-vtype``): an air a vehicle drives in."""
    if t is None:
        return
    from sumo_drvpw.sim.scenario_values import AIR_RANGES

    lo, hi = AIR_RANGES["temperature_c"]
    if not lo <= t <= hi:
        raise UserError(f"--air-temperature {t:g}: an air temperature in {lo:g} … {hi:g} °C")


def check_period(period: float | None) -> None:
    """``--period`` (``run``, ``fcd``): an edgeData interval."""
    if period is not None and not 0 < period <= 1e9:
        raise UserError(f"--period {period:g}: an edgeData interval is a number of seconds > 0 and at most 1e9")


def existing_paths(*groups) -> list[str]:
    """The arguments that name existing files or folders (inputs an output must avoid);
    each group is a path, a list of paths or None (names like ``prius3`` are skipped)."""
    from pathlib import Path

    out = []
    for g in groups:
        if g is None:
            continue
        if isinstance(g, (str, Path)):
            if Path(g).exists():
                out.append(str(g))
        else:  # a list of paths, or of lists
            out += existing_paths(*g)
    return out


def output_set(args, out, inputs=(), meta=None):
    """:func:`sumo_drvpw.fileio.output_set` for a command: ``--force`` from ``args``."""
    from sumo_drvpw import fileio

    return fileio.output_set(out, force=bool(getattr(args, "force", False)),
                             inputs=existing_paths(inputs), meta=meta)


def add_log_options(p) -> None:
    """How drive logs are read: --speed-unit and --negative-speed-tolerance
    (:func:`add_read_options`), and the measurement corrections."""
    from sumo_drvpw.cli._measurement import add_corrections

    add_read_options(p)
    add_corrections(p)


def add_read_options(p) -> None:
    """--speed-unit, --negative-speed-tolerance and --flat-road."""
    g = p.add_argument_group("reading drive logs")
    g.add_argument("--speed-unit", choices=("m/s", "km/h", "mph"),
                   help="unit of the logs' speed_mps column (default m/s, checked: speeds whose implied "
                        "accelerations only make sense in km/h are refused; m/s = trust the log)")
    g.add_argument("--negative-speed-tolerance", type=float, default=0.1, metavar="M_S",
                   help="speeds in [-M_S, 0) are standstill noise, clipped to 0 and counted (default 0.1)")
    g.add_argument("--flat-road", action="store_true", help="read the logs as a flat road: no grade from grade_rad, "
                   "grade_pct or elevation_m (a phone's GPS altitude: noise; --air-density altitude still reads it)")


def chains_fuel(equations) -> str | None:
    """The one fuel the fuel chains of ``equations`` (names or files) burn, None when none
    has a fuel chain or they burn several: a fuel flow is read as it when no vehicle file
    names a fuel (:func:`sumo_drvpw.data.powertrain.measured_fuel`). An equation that does
    not load is left to the command's own error."""
    from sumo_drvpw.model.equations import SPEC_EQUATIONS, load_equation

    fuels = set()
    for spec in equations or ():
        if not isinstance(spec, str) or spec in SPEC_EQUATIONS:
            continue
        try:
            ch = load_equation(spec).chain
        except UserError:
            continue
        if ch is not None and ch.predicts == "fuel":
            fuels.add(ch.fuel or "gasoline")
    return fuels.pop() if len(fuels) == 1 else None


def read_options(args, equations=()):
    """:class:`sumo_drvpw.data.log.ReadOptions` from the options of :func:`add_log_options`
    (measurement corrections: :func:`sumo_drvpw.cli._measurement.measurement_options`, each
    flag given over its own setting of the equations' ``[measurement]``)."""
    from sumo_drvpw.cli._measurement import measurement_options
    from sumo_drvpw.data.log import ReadOptions, check_options

    tol = getattr(args, "negative_speed_tolerance", None)
    opt = ReadOptions(speed_unit=getattr(args, "speed_unit", None),
                      negative_speed_tolerance_mps=0.1 if tol is None else tol,
                      measurement=measurement_options(args, equations), fuel=chains_fuel(equations),
                      flat_road=bool(getattr(args, "flat_road", False)))
    if opt.flat_road and getattr(opt.measurement, "grade", "logged") != "logged":
        raise UserError(f"--flat-road sets the logs' grade aside, the grade source '{opt.measurement.grade}' "
                        "(--grade-source, or the equations' [measurement]) reads it: give one of them")
    try:
        opt = check_options(opt)
    except UserError as e:
        raise UserError(f"--negative-speed-tolerance / --speed-unit: {e}") from None
    if getattr(args, "logs", None):  # a log `import` wrote is in m/s already
        from sumo_drvpw.data.log import check_declared_unit

        check_declared_unit(args.logs, opt)
    return opt


#: share of a log's samples left out as steeper than any road above which its elevation is read as noise
#: (a phone's GPS altitude: 6.7 % on a flat coastal Torque Pro trip, ±150 m; none on the i3, JLU, Prius logs)
NOISY_ELEVATION_SHARE = 0.02


def say_traction_only(counts: dict) -> None:
    """Warn when the measured power hardly ever goes negative where the car brakes hard
    (:func:`sumo_drvpw.data.measured.braking_counts`)."""
    from sumo_drvpw.data.measured import BRAKING_PROXY_W, RECUPERATING_W, TRACTION_ONLY_MIN_BRAKING, TRACTION_ONLY_SHARE

    n, k = int(counts.get("braking_samples", 0) or 0), int(counts.get("braking_recuperating", 0) or 0)
    if n >= TRACTION_ONLY_MIN_BRAKING and k < TRACTION_ONLY_SHARE * n:
        print(f"warning: the measured power is below {RECUPERATING_W / 1000:g} kW in only {k} of {n} samples "
              f"where the car brakes (m·v·(a + g·sin θ) below {BRAKING_PROXY_W / 1000:g} kW): the log records "
              "traction only (a motor power or engine estimate that is never negative), not what braking "
              "returns; a driving-power equation fitted on it is biased and a battery chain gets no "
              "recuperation — use a signed power (battery V·I, motor torque × speed)")


def note_counts(counts: dict) -> None:
    """Print what the log reader changed or assumed (e.g. clipped standstill noise)."""
    from sumo_drvpw.data.conditions import speed_gps_note
    from sumo_drvpw.data.plausible import speed_step_note
    from sumo_drvpw.data.truncated import cut_message

    for f, row in (counts.get("truncated_rows") or {}).items():  # CSV files cut inside their last row
        print(f"warning: {cut_message(f, row)}")
    gaps = int(counts.get("time_gaps", 0) or 0)
    if gaps:  # pauses in logging inside trips: weigh nothing (counted in the reports, said here)
        print(f"note: {gaps} pause(s) in logging inside trips, {float(counts.get('time_gaps_s', 0.0)):.4g} s in "
              "all: no energy is booked over them and no derivative reaches across them")
    say_traction_only(counts)
    moving, held = int(counts.get("moving_rows", 0) or 0), int(counts.get("held_moving_rows", 0) or 0)
    if moving >= 100 and held > 0.5 * moving:  # a logger's held values: fewer independent samples
        k = moving / max(moving - held, 1)
        print(f"note: {held / moving:.0%} of the moving rows repeat the row before (speed and measured power "
              f"alike): values held between the logger's updates, about one new value per {k:.1f} rows; fitted "
              f"standard errors and p-values count every row, so the errors are about {k ** 0.5:.1f}× too small "
              "(and stepwise selection too willing)")
    if counts.get("excluded_speed_step"):  # a splice, a speed lost and found (data/plausible.py speed_steps)
        print(f"note: {speed_step_note(counts)}")
    n = int(counts.get("clipped_negative_speed", 0) or 0)
    if n:
        tol = counts.get("negative_speed_tolerance_mps", 0.1)
        print(f"note: {n} speed sample(s) in [-{tol:g}, 0) m/s clipped to 0 (standstill sensor noise)")
    if counts.get("speed_unit"):
        print(f"note: speed_mps read in {counts['speed_unit']}")
    if any(w in str(counts.get("accel_source", "")) for w in ("widened", "held between updates")):
        print(f"note: acceleration {counts['accel_source'].split('derived: ', 1)[-1]}")
    parts = [f"{counts[k]} row(s) {what}" for k, what in (
        ("accel_derived_rows", "without accel_mps2 took the acceleration derived from the speed"),
        ("mass_from_vehicle_rows", "without mass_kg took the vehicle's mass"),
        ("grade_filled_rows", "without grade_rad or grade_pct took their elevation's grade, else a flat road"))
        if counts.get(k)]
    if parts:  # trips with no value in a column (in a folder: files without it), as read alone
        print("note: trips with no value in a column, read as a file without it: " + "; ".join(parts))
    grade_by = str((counts.get("measurement") or {}).get("grade", ""))
    if str(counts.get("grade_source", "")).startswith("none (") and grade_by != "accelerometer":
        print("note: the logs carry no grade (no grade_rad, grade_pct or elevation_m values): a flat road "
              "is assumed, so a trip that climbs or descends Δh misses m·g·Δh (1.5 t over 100 m: "
              "0.41 kWh); log the elevation (e.g. GPS altitude) where the routes are not flat")
    flat = counts.get("grade_flat_trips") or []
    if flat and not str(counts.get("grade_source", "")).startswith("none"):
        print(f"note: {len(flat)} trip(s) without elevation read as a flat road ({', '.join(flat[:10])}"
              f"{', …' if len(flat) > 10 else ''}): their climbs and descents are not in their energy")
    n = int(counts.get("elevation_missing_samples", 0) or 0)
    if n:
        print(f"note: {n} sample(s) without elevation (no GPS fix?): the elevation is bridged between the "
              "samples that have it, and held flat before the first and after the last")
    gps = speed_gps_note(counts)  # (data/conditions.speed_against_gps)
    if gps:
        print(f"note: {gps}")
    scales = counts.get("speed_scale") or {}
    if scales:  # (data/corrections.scale_speed)
        ks = sorted(scales.values())
        print(f"note: speed scaled by {ks[0]:.4f}" + (f"–{ks[-1]:.4f}" if ks[-1] != ks[0] else "")
              + f" over {len(ks)} trip(s)" + (f" (against {counts['speed_scale_column']})" if counts.get("speed_scale_column") else ""))
    held = counts.get("elevation_no_fix_values") or []
    if held:  # (data/conditions.no_fix_elevations)
        print(f"note: elevation_m jumps to {', '.join(f'{x:g}' for x in held[:5])} m and back, {int(counts.get('elevation_no_fix_samples', 0) or 0)} "
              "sample(s) in all, far from the rest of their trips: a logger's value for 'no fix', not a height — "
              "declare it no reading (na_values in a mapping's column) so that the elevation is bridged over it")
    n = int(counts.get("excluded_grade_outlier", 0) or 0)
    if n:
        lim = float(counts.get("grade_outlier_limit", 0.35))
        share = n / max(int(counts.get("rows", 0) or 0), 1)
        print(f"note: {n} sample(s) with a grade steeper than {100 * lim:.0f} % left out: no road is that "
              f"steep; an elevation glitch (GPS altitude settling or jumping) put it there "
              f"(source: {counts.get('grade_source', '?')})"
              + (f"; at {100 * share:.1f} % of the samples the elevation is noise, not glitches: its noise is "
                 "in the grade of the samples kept too, booked as climbs and descents (see the grade term's "
                 "energy share in compare); where the roads are flat, read the logs as such (--flat-road)"
                 if share >= NOISY_ELEVATION_SHARE else ""))
    n = int(counts.get("grade_elevation_gap_trips", 0) or 0)
    if n:
        gaps = sorted((counts.get("grade_elevation_gap_m") or {}).items(), key=lambda tg: -abs(tg[1]))[:10]
        listed = ", ".join(f"{t} {g:+.0f} m" for t, g in gaps)
        print(f"note: on {n} trip(s) the corrected grade integrates to an elevation change more than 20 m "
              f"away from the logged one ({listed}{', …' if n > len(gaps) else ''}): "
              "their grade energy (m·g × that gap) is uncertain; a shorter --grade-source fused:TAU_Ss "
              "keeps closer to the elevation, a fusion over driven distance (fused:1000m) keeps it")


def _driving_power_hint(e: NoDrivingPower, args) -> str:
    """What a log without a driving power can still do, in the command's flags: an energy
    chain's road load from --equation, or the fuel target the log holds."""
    target = getattr(args, "target", None)
    if target in ("battery", "fuel") and getattr(args, "equation", None) is None:
        return ("; the chain needs a road load to sit on: give it with --equation (vsp_spec: the "
                "vehicle file's [body]; roadload_spec: its published A + B·v + C·v²; or an equation "
                "calibrated on logs with a driving power)")
    for kind in ("fuel", "battery"):
        if kind in e.targets and target in (None, "wheel"):
            return (f"; calibrate its {kind} chain with `sumo-drvpw calibrate LOG --vehicle V --target {kind} "
                    "--equation vsp_spec|roadload_spec|EQ --out CHAIN.toml`, then compare or diagnose with "
                    f"--target {kind} --equation CHAIN.toml")
    return ""


#: plain stand-ins for the symbols the reports print, on a console that cannot show them
_PLAIN = str.maketrans({"→": "->", "←": "<-", "−": "-", "–": "-", "—": "-", "≥": ">=", "≤": "<=",
                        "≈": "~", "±": "+/-", "×": "x", "·": "*", "Δ": "d", "Σ": "sum", "η": "eta",
                        "ρ": "rho", "σ": "sigma", "θ": "theta", "²": "^2", "³": "^3", "₂": "2",
                        "√": "sqrt", "…": "...", "‘": "'", "’": "'", "“": '"', "”": '"'})


def _encodable(text: str, stream) -> str:
    """``text`` as the stream's encoding can write it: the reports' symbols in plain
    characters, anything else escaped (a Latin-1 or cp1252 console: no traceback)."""
    enc = getattr(stream, "encoding", None) or "ascii"
    return text.translate(_PLAIN).encode(enc, "backslashreplace").decode(enc)


class _ClosedPipeSafe:
    """Standard output or error that goes on when its reader has gone (``sumo-drvpw … | head``):
    the first broken pipe points the descriptor at /dev/null (the idiom of Python's signal
    documentation, "Note on SIGPIPE") and later writes are dropped, so the command finishes
    its work and writes its outputs instead of stopping with a traceback."""

    def __init__(self, stream):
        self._stream, self.closed_reader = stream, False

    def _guard(self, op, *a):
        if self.closed_reader:
            return None
        try:
            return op(*a)
        except BrokenPipeError:
            self.closed_reader = True
            try:
                devnull = os.open(os.devnull, os.O_WRONLY)
                os.dup2(devnull, self._stream.fileno())
            except (OSError, ValueError, AttributeError):  # no descriptor (a test's capture)
                pass
            return None

    def write(self, text):
        enc = str(getattr(self._stream, "encoding", None) or "utf-8")
        if not enc.lower().replace("-", "").startswith("utf"):  # a console whose encoding lacks
            try:                                                # →, Δ, − (Latin-1, cp1252):
                text.encode(enc)                                # plain stand-ins, on stderr too
            except (UnicodeEncodeError, LookupError):          # (which escapes them itself)
                text = _encodable(text, self._stream)
        r = self._guard(self._stream.write, text)
        return len(text) if r is None else r

    def flush(self):
        self._guard(self._stream.flush)

    def __getattr__(self, name):
        return getattr(self._stream, name)


def main(argv: list[str] | None = None) -> int:
    from sumo_drvpw import fileio

    entry = argv is None  # the process's own command line: it exits when main returns
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser(lazy=True)
    args = parser.parse_args(argv)
    if getattr(args, "_missing", None):
        print(f"sumo-drvpw: error: command '{args.command}' is not available in this build",
              file=sys.stderr)
        return 2
    fileio.CURRENT_COMMAND = ["sumo-drvpw", *argv]
    prev_stdout, prev_stderr = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = _ClosedPipeSafe(prev_stdout), _ClosedPipeSafe(prev_stderr)
    prev_term = prev_int = None
    prev_hook, sys.unraisablehook = sys.unraisablehook, _quiet_signal_hook(sys.unraisablehook)
    try:  # only the main thread may install handlers (tests may call main elsewhere)
        prev_term = signal.signal(signal.SIGTERM, _on_sigterm)
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            prev_int = signal.signal(signal.SIGINT, _on_sigint)
    except ValueError:
        pass
    try:
        # numeric warnings (empty slices, 0/0) are handled by the code, library warnings
        # address developers: none reach the user's terminal unless asked for with
        # python -W / PYTHONWARNINGS (the idiom of the warnings module's documentation)
        with warnings.catch_warnings():
            if not sys.warnoptions:
                warnings.simplefilter("ignore")
            import numpy as np

            with np.errstate(all="ignore"):
                rc = int(args._main(args) or 0)
            # a command that caught the interrupt itself (run writes what it simulated)
            if rc == 130 and _TERMINATED:
                return 128 + signal.SIGTERM
            if rc == 0 and (_TERMINATED or _INTERRUPTED):  # a library swallowed the signal
                return _signal_exit(bool(_TERMINATED), finished=True)
            return rc
    except OutputExists as e:
        print(f"sumo-drvpw {args.command}: error: {_one_line(e)}; give --force to replace it",
              file=sys.stderr)
        return 2
    except NoDrivingPower as e:
        print(f"sumo-drvpw {args.command}: error: {_as_typed(_one_line(e), args)}{_driving_power_hint(e, args)}",
              file=sys.stderr)
        return 2
    except UserError as e:
        print(f"sumo-drvpw {args.command}: error: {_as_typed(_one_line(e), args)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as e:  # SIGINT, or SIGTERM as _Terminated
        return _signal_exit(isinstance(e, _Terminated))
    except OSError as e:
        rc = _stopped_by_signal()
        if rc is not None:
            return rc
        if e.errno == errno.ENOENT and e.filename is None and "temporary directory" in str(e.strerror):
            print(f"sumo-drvpw {args.command}: error: no usable temporary folder (TMPDIR, /tmp, /var/tmp and "
                  "the working folder cannot be written): set TMPDIR to a writable folder", file=sys.stderr)
            return 2
        if e.errno in (errno.ENOSPC, errno.EDQUOT):
            print(f"sumo-drvpw {args.command}: error: disk full (no space left on the device) "
                  f"while writing {e.filename or 'the output'}", file=sys.stderr)
            return 2
        raise
    except Exception:
        rc = _stopped_by_signal()
        if rc is not None:
            return rc
        raise
    finally:
        fileio.CURRENT_COMMAND = None
        for name, prev in (("stdout", prev_stdout), ("stderr", prev_stderr)):
            if isinstance(getattr(sys, name), _ClosedPipeSafe):
                getattr(sys, name).flush()  # a pipe's buffer is written here, not at exit unguarded
                setattr(sys, name, prev)
        # (restored last: a stop's signal sent again until here is absorbed; a process stopping on
        # one ignores it from here to its exit — a library's late re-send killed it by SIGINT, exit −2)
        stopping = entry and bool(_TERMINATED or _INTERRUPTED)
        if prev_term is not None:
            signal.signal(signal.SIGTERM, signal.SIG_IGN if stopping else prev_term)
        if prev_int is not None:
            signal.signal(signal.SIGINT, signal.SIG_IGN if stopping else prev_int)
        _TERMINATED.clear()
        _INTERRUPTED.clear()
        sys.unraisablehook = prev_hook


#: what a library message calls an option (it names no flags) → the flag the user types,
#: for the commands that have it (argparse attribute)
_FLAGS = (("speed_unit", "declare the unit (speed unit km/h or m/s)",
           "declare the unit (--speed-unit km/h, or --speed-unit m/s to keep it)"),
          ("speed_unit", "read it with speed unit km/h", "read it with --speed-unit km/h"),
          ("exclude_dropouts", "cannot be told from a held value",
           "cannot be told from a held value (--no-exclude-dropouts keeps them)"),
          ("fit_window", "energy chain: windows of ", "--fit-window: windows of "))


#: the same for a [measurement] setting a library message names with its value: the flag that sets it
_SETTINGS = (("speed_scale", r'speed_scale = "(gps:[^"]+)" or "(gps:[^"]+)"',
              r'--speed-scale \1 or --speed-scale \2 (in an equation file: speed_scale = "\1")'),)


def _as_typed(msg: str, args) -> str:
    """A library message with its option names as the user types them on this command."""
    import re

    for attr, said, typed in _FLAGS:
        if hasattr(args, attr):
            msg = msg.replace(said, typed)
    for attr, said, typed in _SETTINGS:
        if hasattr(args, attr):
            msg = re.sub(said, typed, msg)
    if hasattr(args, "speed_scale") and re.search(r"speed scale '[^']*'", msg):  # where it was said
        from sumo_drvpw.cli._measurement import speed_scale_origin

        src = speed_scale_origin(args)
        if src is not None:
            msg = re.sub(r"speed scale '([^']*)'", lambda m: f"{src} {m[1]}" if src.startswith("--")
                         else f'{src} = "{m[1]}"', msg)
    return msg


def _one_line(e: Exception) -> str:
    """An error's text on one line (a library's message may end in or hold line breaks)."""
    return "; ".join(x.strip() for x in str(e).splitlines() if x.strip())


if __name__ == "__main__":
    sys.exit(main())
