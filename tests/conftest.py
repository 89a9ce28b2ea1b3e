"""Shared fixtures: the real data beside the repository (skipped cleanly when absent), and the
compiled plank scenes of the trial tests (:mod:`planks`)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import pytest
from planks import LONG_PLANK, SHORT_PLANK, plank

if TYPE_CHECKING:  # the scenes import MuJoCo: only the tests that use them pay for it
    from dg16m_env.physics.scene import Scene

REAL_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"


@pytest.fixture(scope="session")
def real_data() -> Path:
    """``../shared/data/real``; tests using it skip when it is not there."""
    if not (REAL_DATA / "dg16m_airplane.h5").is_file():
        pytest.skip(f"real data not found at {REAL_DATA}")
    return REAL_DATA


@pytest.fixture(scope="module")
def short_scene() -> Scene:
    """0.6 m, 4 kg plank."""
    from dg16m_env.physics.scene import compile_scene

    return compile_scene(plank(*SHORT_PLANK))


@pytest.fixture(scope="module")
def long_scene() -> Scene:
    """1.0 m, 6 kg plank."""
    from dg16m_env.physics.scene import compile_scene

    return compile_scene(plank(*LONG_PLANK))
