"""sumo-drvpw: driving power and energy per term for SUMO vehicles."""

from importlib.metadata import PackageNotFoundError, version as _dist_version

try:
    __version__ = _dist_version("sumo-drvpw")
except PackageNotFoundError:  # run from a source tree without installing
    __version__ = "0+unknown"
