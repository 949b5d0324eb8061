"""The one exception type for user mistakes: the CLI prints its message and exits 2."""


class UserError(Exception):
    """Bad input from the user (file, column, option, value).

    The message names the file, column or option and the first offending row or value.
    The CLI prints it without a traceback and exits with code 2.
    """


def first_bad_row(mask, index=None) -> str:
    """Describe the first True position of a boolean mask as 'row N' (0-based data row)."""
    import numpy as np

    pos = int(np.flatnonzero(np.asarray(mask))[0])
    label = pos if index is None else index[pos]
    return f"row {label}"


class OutputExists(UserError):
    """An output folder exists with files not written by sumo-drvpw.

    The CLI adds how to replace it anyway (``--force``); library code never names flags.
    """
