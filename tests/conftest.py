"""Shared fixtures: paths to bundled data and to the shared real data."""

import os
from pathlib import Path

import pytest
from hypothesis import settings

# Property tests draw the same examples on every run and every machine (seeded from each
# test's source), so the README's test command passes or fails the same way on a fresh
# clone as here; a failure names its example and reproduces. To search new examples (as
# a developer should before a change lands): HYPOTHESIS_PROFILE=explore python -m pytest -q
settings.register_profile("repeatable", derandomize=True, print_blob=True)
settings.register_profile("explore", derandomize=False, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "repeatable"))

# No network table kept on disk between tests (sim/net_cache.py): a test that patches the
# network's computation sees it run, and the user's cache folder is not written
# (tests/test_sim_net_cache.py turns the cache on in a folder of its own)
os.environ["SUMO_DRVPW_CACHE"] = "off"

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
