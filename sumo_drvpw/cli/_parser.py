"""The command line's argument parser: one line and exit 2 on a bad argument, and an option
that holds one value refused when given twice with different values."""

from __future__ import annotations

import argparse


def _shown(value) -> str:
    """An option's parsed value as typed (600 rather than 600.0)."""
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, (list, tuple)):
        return " ".join(_shown(v) for v in value)
    return str(value)


def _given_once(base):
    """``base`` (an argparse action storing one value) refusing its option given twice with
    different values (``--end 600 --end 900``: argparse keeps the last silently)."""

    class Once(base):
        def __call__(self, parser, namespace, values, option_string=None):
            given = namespace.__dict__.setdefault("_given", {})
            if option_string is not None:
                value = self.const if self.nargs == 0 else values  # (a switch: what it sets)
                first = given.get(self.dest)
                if first is not None and first[1] != value:
                    if first[0] != option_string:  # two options of one setting (--x and --no-x)
                        parser.error(f"{first[0]} and {option_string} set one thing two ways: give one")
                    parser.error(f"{option_string} given twice ({first[0]} {_shown(first[1])}, then "
                                 f"{option_string} {_shown(values)}): give it once")
                given[self.dest] = (option_string, value)
            super().__call__(parser, namespace, values, option_string)

    return Once


def path_arg(value: str) -> str:
    """A file or folder argument: an empty or blank one ('--vtypes ""', a shell variable left
    unset) names no file — refused, not read as the working folder."""
    if not value.strip():
        raise argparse.ArgumentTypeError(f"an empty path ({value!r} names no file)")
    return value


class _Parser(argparse.ArgumentParser):
    def __init__(self, *a, **kw):
        super().__init__(*a, **kw)
        for name, base in ((None, argparse._StoreAction), ("store", argparse._StoreAction),
                           ("store_true", argparse._StoreTrueAction),
                           ("store_false", argparse._StoreFalseAction)):
            self.register("action", name, _given_once(base))

    def error(self, message):  # exit 2 with one line, as for every other bad input
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")
