"""Shared test fixtures: paths to the reference data beside the project."""

from __future__ import annotations

from pathlib import Path

import pytest

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
OCTOMAP_DATA = SHARED / "data" / "octomap"


@pytest.fixture(scope="session")
def octomap_data() -> Path:
    assert (OCTOMAP_DATA / "scan.dat.bz2").is_file(), f"reference data missing: {OCTOMAP_DATA}"
    return OCTOMAP_DATA
