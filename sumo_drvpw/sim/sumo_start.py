"""Starting and closing SUMO for a run: in process (libsumo) or as a TraCI server, with
SUMO's own start-up errors in one line of ours (the first malformed input file named), and
sumo-gui refused at once where no display answers."""

from __future__ import annotations

import contextlib
import functools
import os
import sys
from pathlib import Path

from sumo_drvpw.errors import UserError
from sumo_drvpw.fileio import signals_blocked

__all__ = ["start_sumo", "close_sumo", "step_method", "scenario_option", "signals_deferred",
           "NewRun", "check_option_values"]


#: SUMO options (without their dashes) after which it runs no simulation here, and what they do instead
NO_RUN_OPTIONS = {"help": "prints SUMO's help and exits", "?": "prints SUMO's help and exits",
                  "version": "prints SUMO's version and exits", "V": "prints SUMO's version and exits",
                  "save-configuration": "writes a config and exits", "C": "writes a config and exits",
                  "save-template": "writes a template and exits", "save-schema": "writes a schema and exits",
                  "remote-port": "makes SUMO wait for a TraCI client (but 0, no server)",
                  "num-clients": "makes SUMO wait for TraCI clients (but 1)"}


def option_types() -> dict[str, str]:
    """SUMO's options by every name they go by (long names and synonyms: "route-files", "r",
    "routes") → their type as SUMO's template writes it (BOOL, FILE, TIME, INT, …), from
    ``sumo --save-template stdout``; {} where SUMO cannot be asked."""
    return {n: t for n, (_, t) in option_template().items()}


#: SUMO's options that name the files it reads (long names), and what an empty one does
INPUT_LISTS = {"route-files": "it would load no routes, and run no vehicle", "net-file": "it would load no network",
               "additional-files": "it would load none", "configuration-file": "it would load no config"}


@functools.lru_cache(maxsize=1)
def option_template() -> dict[str, tuple[str, str]]:
    """SUMO's options by every name they go by → (their long name, their type): SUMO's template,
    read once per process (:func:`option_types`)."""
    import subprocess
    import xml.etree.ElementTree as ET

    import sumolib

    _sumo_env()
    try:
        out = subprocess.run([sumolib.checkBinary("sumo"), "--save-template", "stdout"],
                             capture_output=True, timeout=60, check=True).stdout
        root = ET.fromstring(out)
    except (OSError, subprocess.SubprocessError, ET.ParseError):
        return {}
    return {n: (opt.tag, opt.get("type")) for section in root for opt in section if opt.get("type")
            for n in (opt.tag, *opt.get("synonymes", "").split())}


def _is_number(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def check_option_values(options: list[str], where: str, given: dict[str, str] | None = None) -> None:
    """A scenario's SUMO ``options`` (its ``sumo.options``: the end of SUMO's command line)
    checked against SUMO's own options (:func:`option_types`): each is one of them, and each
    that takes a value (all but SUMO's true/false flags) is given one, as its own item after
    it or as ``--key=value``. SUMO would read a missing value as "true" or take the next option
    for it, and says of that, of a misspelt option, a stray value or "--seed 7" in one item only
    "The parameter '…' is not allowed in this context". UserError naming the item. An option the
    plug-in's own command line sets already (``given``: its long name → what sets it, "sumo.end
    (100 s)") is a UserError naming both: SUMO says only "A value for the option 'end' was already set"."""
    template = option_template() if options else {}
    types = {n: t for n, (_, t) in template.items()}
    i = 0
    while types and i < len(options):
        a = str(options[i])
        if not a.startswith("-") or _is_number(a):
            raise UserError(f"{where}: sumo.options: {a!r} is neither a SUMO option nor an option's value (an option "
                            'starts with "-"; its value is the next item: ["--time-to-teleport", "120"])')
        kind = types.get(a.lstrip("-").partition("=")[0])
        if kind is None:
            raise UserError(f"{where}: sumo.options: {a!r} is no option of SUMO's (a typo? sumo --help lists them)"
                            + ('; give each option and value an item of its own: ["--time-to-teleport", "120"]' * (" " in a)))
        long = template[a.lstrip("-").partition("=")[0]][0]
        if long in (given or {}):
            said = f"{a!r}" + (f" (SUMO's --{long})" if a.lstrip("-").partition("=")[0] != long else "")
            raise UserError(f"{where}: sumo.options: {said} is set by {given[long]} already, and SUMO takes an "
                            "option once: give it there alone")
        nxt = str(options[i + 1]) if i + 1 < len(options) else None
        if "=" in a:
            val = a.partition("=")[2]
        elif kind != "BOOL":
            if nxt is None or (nxt.startswith("-") and not _is_number(nxt)):
                raise UserError(f"{where}: sumo.options: {a!r} takes a value (SUMO's {kind}) and is given "
                                f"{'none' if nxt is None else f'none before {nxt!r}'}: write "
                                f'["{a}", "<value>"] (or leave {a} out)')
            val, i = nxt, i + 1
        elif nxt is not None and nxt.lower() in ("true", "false", "yes", "no", "on", "off", "1", "0", "x"):
            i += 1  # "--verbose false", as SUMO reads it
        if long in INPUT_LISTS and not any(x.strip() for x in val.split(",")):  # (a file list: never a flag)
            # ("--route-files=": SUMO ran no vehicle, and warned only of that)
            raise UserError(f"{where}: sumo.options: {a!r}{'' if '=' in a else f' {val!r}'} gives SUMO's --{long} no "
                            f"file: {INPUT_LISTS[long]}; name its files, or leave the option out")
        i += 1


class NewRun(UserError):
    """SUMO's time went back from ``last_t`` to ``t_now`` [s]: a new run began (a load(), or
    a libsumo session started after the close of the one booked)."""

    def __init__(self, last_t: float, t_now: float):
        self.last_t, self.t_now = last_t, t_now
        super().__init__(f"Accountant: simulation time went back from {last_t:g} s to {t_now:g} s "
                         "(traci.load / simulation.load?): an Accountant books one run; take its "
                         "result() before the load and start a new one after it")


def _sumo_env() -> None:
    if not os.environ.get("SUMO_HOME"):
        try:
            import sumo

            os.environ["SUMO_HOME"] = sumo.SUMO_HOME
        except ImportError:
            pass


@contextlib.contextmanager
def _sumo_output():
    """Capture what in-process SUMO (libsumo) writes to the process's stdout and stderr
    while it starts: yields (stdout lines, stderr lines), filled on exit."""
    import tempfile

    got: tuple[list[str], list[str]] = ([], [])
    sys.stdout.flush()
    sys.stderr.flush()
    try:
        saved = [os.dup(1), os.dup(2)]
    except OSError:  # no descriptors to redirect: leave them as they are
        yield got
        return
    caps = [tempfile.TemporaryFile(mode="w+b"), tempfile.TemporaryFile(mode="w+b")]
    try:
        for fd, cap in zip((1, 2), caps):
            os.dup2(cap.fileno(), fd)
        yield got
    finally:
        for fd, keep, cap, lines in zip((1, 2), saved, caps, got):
            os.dup2(keep, fd)
            os.close(keep)
            cap.seek(0)
            lines += cap.read().decode("utf-8", "replace").splitlines(keepends=True)
            cap.close()


#: device → the explicit vehicle list (``device.<device>.explicit``) the first libsumo run of
#: this process set: libsumo keeps it for the process's life (SUMO's MSDevice fills its
#: explicit ids once per device), so a later run in the process naming another list equipped
#: the first run's vehicles (a sweep run one after the other, a notebook's runs)
_EXPLICIT_SEEN: dict[str, str] = {}


def explicit_lists(args: list[str]) -> dict[str, str]:
    """Each device's explicit vehicle list that SUMO's ``args`` set: an option (empty too), else
    a non-empty ``<device.X.explicit value=…/>`` of the config ``-c`` names."""
    import re

    from sumo_drvpw.sim.scenario_paths import config_files

    out: dict[str, str] = {}
    for i, a in enumerate(args[:-1]):
        if a == "-c" and Path(args[i + 1]).is_file():
            for k, v in config_files(Path(args[i + 1]))[2].items():
                if (m := re.fullmatch(r"device\.(.+)\.explicit", k)) and str(v).strip():
                    out[m[1]] = str(v)
    for i, a in enumerate(args):
        if m := re.fullmatch(r"--device\.(.+)\.explicit(?:=(.*))?", a):
            out[m[1]] = m[2] if m[2] is not None else (args[i + 1] if i + 1 < len(args) else "")
    return out


def start_sumo(args: list[str], connection: str = "libsumo", gui: bool = False,
               label: str = "drvpw"):
    """Start SUMO with command-line ``args``; returns the connection. UserError on failure.
    A libsumo run whose device explicit vehicle lists differ from those an earlier libsumo
    run of this process set (:data:`_EXPLICIT_SEEN`) runs over TraCI, in a SUMO of its own."""
    import sumolib

    _sumo_env()
    lists = explicit_lists(args)
    if connection == "libsumo" and any(_EXPLICIT_SEEN.get(d, v) != v for d, v in lists.items()):
        connection = "traci"
    if gui and sys.platform.startswith("linux") and not os.environ.get("WAYLAND_DISPLAY"):
        display = os.environ.get("DISPLAY")
        if not display:
            raise UserError("sumo.gui: no display to show sumo-gui on (DISPLAY is not set); run "
                            "without the GUI, or where a display is")
        if not _display_reachable(display):  # sumo-gui would retry for a minute, then fail
            raise UserError(f"sumo.gui: cannot reach the display DISPLAY={display!r} (no X server "
                            "answers there); run without the GUI, or where a display is")
    binary = sumolib.checkBinary("sumo-gui" if gui else "sumo")
    cmd = [binary, *args]
    if not any(a == "--no-step-log" or a.startswith("--no-step-log=") for a in args):
        cmd += ["--no-step-log", "true"]  # given twice, SUMO refuses to start (its own tests give it)
    if connection == "libsumo":
        if gui:
            raise UserError("sumo.gui needs connection = 'traci'")
        import libsumo

        if not any(a == "--remote-port" or a.startswith("--remote-port=") for a in args):
            # a config written for TraCI scripts may set remote-port (sumo-rl's OW-traci.sumocfg:
            # 8813): SUMO would then wait for a client that never comes; in-process, none is needed
            cmd += ["--remote-port", "0"]

        with _sumo_output() as (told, said):
            try:
                libsumo.start(cmd)
                failed = None
            except Exception as e:  # libsumo.TraCIException / FatalTraCIError
                failed = e
                try:
                    libsumo.close()
                except Exception:
                    pass
        if failed is not None:  # SUMO's own error lines, in the one line of ours
            why = "; ".join(_error_lines(said)) or str(failed)
            raise UserError(f"SUMO failed to start ({' '.join(args)}): {why}{_malformed(args)}"
                            ) from None
        sys.stdout.write("".join(told))  # started: what SUMO wrote goes on as it wrote it
        sys.stderr.write("".join(said))
        for d, v in lists.items():
            _EXPLICIT_SEEN.setdefault(d, v)
        return libsumo
    import traci

    try:
        traci.start(cmd, label=label, stdout=open(os.devnull, "w"))
    except Exception as e:  # traci.exceptions.FatalTraCIError, OSError
        raise UserError(f"SUMO failed to start ({' '.join(args)}): {e}{_malformed(args)}"
                        ) from None
    return traci.getConnection(label)


def _error_lines(said: list[str]) -> list[str]:
    """SUMO's error lines among the lines it wrote, each with the indented lines that go on
    with it ("Error: While processing option 'seed':" and " 'abc' is not a valid integer.")."""
    out: list[str] = []
    for x in said:
        if x.strip().startswith("Error"):
            out.append(x.strip())
        elif out and x[:1] in (" ", "\t") and x.strip():
            out[-1] += " " + x.strip()
    return out


def _display_reachable(display: str, timeout_s: float = 2.0) -> bool:
    """Whether an X server answers at ``display`` ("[host]:N[.S]"): its Unix socket (also
    Linux's abstract one) for a local display, TCP port 6000 + N for a remote one."""
    import socket

    host, _, num = display.rpartition(":")
    try:
        n = int(num.split(".")[0])
    except ValueError:
        return False
    if host in ("", "unix"):
        for path in (f"/tmp/.X11-unix/X{n}", f"\0/tmp/.X11-unix/X{n}"):
            with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
                s.settimeout(timeout_s)
                try:
                    s.connect(path)
                    return True
                except OSError:
                    continue
        return False
    try:
        socket.create_connection((host, 6000 + n), timeout=timeout_s).close()
        return True
    except OSError:
        return False


def _malformed(args: list[str]) -> str:
    """After SUMO refused to start: '; FILE: not valid XML: ...' for the first of its input
    files (config, net, routes, additional) that is not well-formed, else ''. SUMO's own
    message for a broken net ('input ended before all started tags were ended') names no file."""
    import xml.parsers.expat

    from sumo_drvpw.fileio import open_maybe_gzip
    from sumo_drvpw.sim.scenario_paths import config_files

    files: list[Path] = []
    it = iter(args)
    for a in it:
        val = next(it, "") if a in ("-c", "--configuration-file", "-n", "--net-file", "-r",
                                    "--route-files", "-a", "--additional-files") else None
        if val is None:
            continue
        if a in ("-c", "--configuration-file"):
            files.append(Path(val))
            try:
                net, more, _ = config_files(Path(val))
            except UserError as e:
                return f"; {e}"
            files += [net, *more]
        else:
            files += [Path(f.strip()) for f in val.split(",") if f.strip()]
    for f in files:
        parser = xml.parsers.expat.ParserCreate()
        try:
            with open_maybe_gzip(f) as fh:
                parser.ParseFile(fh)
        except xml.parsers.expat.ExpatError as e:
            return f"; {f}: not valid XML: {e}"
        except (OSError, EOFError, ValueError):
            continue
    return ""


def close_sumo(conn) -> None:
    """Close a connection, ignoring errors of an already closed one."""
    try:
        conn.close()
    except Exception:
        pass


# ---------------------------------------------------------------- SUMO's position update
#: SUMO's words for true in a boolean option
_TRUE = ("true", "1", "yes", "on", "x")


def ballistic_update(given: str | None, action_step: str | None) -> bool:
    """SUMO's rule for its position update (MSFrame::setMSGlobals, SUMO 1.28): ballistic
    when ``step-method.ballistic`` is given true, or when it is not given (``given`` None)
    and ``default.action-step-length`` is (> 0): SUMO then switches to the ballistic update
    ("Integration method was set to 'ballistic' …") while its option still reads false."""
    if given is not None:
        return given.strip().lower() in _TRUE
    try:
        return action_step is not None and float(action_step) > 0
    except ValueError:
        return False


def action_step_switches(action_step_s: float, dt: float) -> bool:
    """Whether a vType's action step length [s] makes SUMO switch the Euler update to the
    ballistic one when a vehicle of it is built and ``step-method.ballistic`` is not given
    (MSVehicleType::check, SUMO 1.28: "Action step length … is used for vehicle type … but
    step-method.ballistic was not set. Setting it now"): a length other than the step
    length ``dt`` [s], as SUMO keeps it — a multiple of the step, at least one step."""
    k = max(1, int(round(float(action_step_s) / dt))) if action_step_s == action_step_s else 1
    return k != 1


def step_method(conn, given: str | None = None) -> str | None:
    """The update a running SUMO moves vehicles by: "euler" (x += v_t·Δt, which position
    tracking relies on), "ballistic" (x += ½(v_t−1 + v_t)·Δt), or None when the connection
    cannot say (the terms then take v_t, as under Euler, and positions are read every
    step). ``given``: the value of ``step-method.ballistic`` the scenario's options or
    config give, if any (:func:`scenario_option`; SUMO's getOption cannot tell a given
    false from the default)."""
    try:
        get = conn.simulation.getOption
        val = str(get("step-method.ballistic")).strip().lower()
    except Exception:  # a fake connection or an old SUMO without getOption
        return None
    if val in _TRUE:
        return "ballistic"
    try:
        action = str(get("default.action-step-length"))
    except Exception:
        action = None
    return "ballistic" if ballistic_update(given, action) else "euler"


def scenario_option(sc, key: str) -> str | None:
    """The value a scenario gives a SUMO option: its SUMO options (``--key value``, a bare
    ``--key`` flag: true, ``--key=value``; the last one wins, as in SUMO), else its
    config's ``<key value=…/>``; None when neither gives it."""
    from sumo_drvpw.sim.scenario_paths import config_files

    args = list(getattr(sc, "sumo_args", ()))
    val = None
    for i, a in enumerate(args):
        if a == "-c" and i + 1 < len(args) and Path(args[i + 1]).is_file():
            val = config_files(Path(args[i + 1]))[2].get(key, val)
    for i, a in enumerate(args):
        if a == f"--{key}":
            nxt = args[i + 1] if i + 1 < len(args) else ""
            val = nxt if nxt and not nxt.startswith("-") else "true"  # a bare flag: true
        elif a.startswith(f"--{key}="):
            val = a.split("=", 1)[1]
    return val


def signals_deferred():
    """Ctrl-C and SIGTERM held back while the block runs (a SUMO step and its booking: else
    SUMO's time could run a step past what was booked, or a step be booked in part), then
    delivered (:func:`sumo_drvpw.fileio.signals_blocked`)."""
    import signal

    return signals_blocked(signal.SIGINT, signal.SIGTERM)
