"""Command line: parses arguments, loads files, calls library functions; no model logic.

Each sub-command lives in the module named in COMMANDS, which defines
``configure(parser)`` (add its arguments) and ``main(args) -> int``. A UserError
anywhere becomes a one-line message on stderr and exit code 2, without a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import sys
import warnings

from sumo_drvpw.errors import UserError

#: sub-command → (module, one-line help)
COMMANDS = {
    "demo": ("sumo_drvpw.cli.demo", "synthesize, calibrate, compare and simulate on bundled data"),
    "synth": ("sumo_drvpw.cli.synth", "generate a synthetic Prius3-like 8 Hz test-track log"),
    "calibrate": ("sumo_drvpw.cli.calibrate", "stepwise-calibrate a DrvPw equation from logs"),
    "compare": ("sumo_drvpw.cli.compare", "compare equations against a log's measured power"),
    "run": ("sumo_drvpw.cli.run", "apply equations to every vehicle of a SUMO scenario"),
    "import": ("sumo_drvpw.cli.import_", "convert vendor logs to canonical drive logs"),
    "validate": ("sumo_drvpw.cli.validate", "validation report on the real data in ../shared/data"),
    "diagnose": ("sumo_drvpw.cli.diagnose", "trace the residual of an equation to missing effects"),
}


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse already exits 2; keep its one-line style
        self.print_usage(sys.stderr)
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="sumo-drvpw", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for name, (module, help_) in COMMANDS.items():
        p = sub.add_parser(name, help=help_, description=help_)
        try:
            mod = importlib.import_module(module)
        except ModuleNotFoundError as e:
            if e.name and e.name.startswith("sumo_drvpw"):
                p.set_defaults(_missing=module)
                continue
            raise
        mod.configure(p)
        p.set_defaults(_main=mod.main)
    return parser


def main(argv: list[str] | None = None) -> int:
    warnings.filterwarnings("ignore", message=".*pyarrow.*")
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "_missing", None):
        print(f"sumo-drvpw: error: command '{args.command}' is not available in this build",
              file=sys.stderr)
        return 2
    try:
        return int(args._main(args) or 0)
    except UserError as e:
        print(f"sumo-drvpw {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("sumo-drvpw: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
