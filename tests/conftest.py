"""Shared fixtures: paths to bundled data and to the shared real data."""

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
BUNDLED_LOG = REPO / "sumo_drvpw" / "data" / "builtin" / "logs" / "prius3_testtrack.parquet"


def shared_data_dir() -> Path | None:
    """`$SUMO_DRVPW_DATA` or `<repo>/../shared/data`, if present."""
    env = os.environ.get("SUMO_DRVPW_DATA")
    p = Path(env) if env else REPO.parent / "shared" / "data"
    return p if p.is_dir() else None


@pytest.fixture
def shared_data():
    p = shared_data_dir()
    if p is None:
        pytest.skip("real data not found: set SUMO_DRVPW_DATA or place it at ../shared/data")
    return p


@pytest.fixture(scope="session")
def bundled_log():
    return BUNDLED_LOG
