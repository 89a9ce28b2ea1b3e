"""Shared fixtures: the real data beside the repository (skipped cleanly when absent)."""

from __future__ import annotations

from pathlib import Path

import pytest

REAL_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"


@pytest.fixture(scope="session")
def real_data() -> Path:
    """``../shared/data/real``; tests using it skip when it is not there."""
    if not (REAL_DATA / "dg16m_airplane.h5").is_file():
        pytest.skip(f"real data not found at {REAL_DATA}")
    return REAL_DATA
