"""Shared test fixtures: paths to the reference data beside the project."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
OCTOMAP_DATA = SHARED / "data" / "octomap"


@pytest.fixture(scope="session")
def octomap_data() -> Path:
    assert (OCTOMAP_DATA / "scan.dat.bz2").is_file(), f"reference data missing: {OCTOMAP_DATA}"
    return OCTOMAP_DATA


def wait_for(cond, what: str, timeout: float = 20.0) -> None:
    """Poll ``cond`` until it holds; a bound on waiting for other threads/processes, not a speed check."""
    end = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > end:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.02)
