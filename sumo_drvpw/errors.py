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


class NoDrivingPower(UserError):
    """A log without a measured driving power (power_w, motor torque, power-split signals,
    battery V·I) where one is needed.

    ``targets`` are the energy targets the log's columns do hold (``"fuel"`` for a fuel or
    mass air flow): the CLI adds the command that uses them; library code never names flags.
    """

    def __init__(self, message: str, targets: tuple = ()):
        super().__init__(message)
        self.targets = tuple(targets)

    def __reduce__(self):  # pickled whole (a Dask task's refusal reaches the driver as it was)
        return (NoDrivingPower, (str(self), self.targets))
