"""The old import paths of ``baselines`` (``pairing`` and ``commands``, renamed for what they
hold) still work for one release and warn, with the mechanism of ``dg16m_core.compat`` (tested
as ``tests/test_layout_compat.py`` tests ``dg16m_env``'s, with its ``fresh_import``)."""

from __future__ import annotations

import importlib
import subprocess
import sys
import warnings

import pytest
from test_layout_compat import fresh_import

import baselines  # noqa: F401  (installs the finder of the old paths)
from baselines._compat import MOVED_MODULES
from dg16m_core.compat import REMOVED_IN


@pytest.mark.parametrize("old", sorted(MOVED_MODULES))
def test_an_old_baselines_module_path_imports_and_warns(old: str) -> None:
    (new,) = MOVED_MODULES[old]
    with pytest.warns(DeprecationWarning, match=rf"{old} moved to {new}.*until dg16m {REMOVED_IN}"):
        module = fresh_import(old)
    assert module is importlib.import_module(new)
    assert module.__name__ == new


def test_what_user_code_names_today_still_works() -> None:
    """A predictor named by its old module path, and the old command module's names."""
    from dg16m_env.subjects.predictor_process import load_target

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        from baselines.commands import register as old_register
        from baselines.pairing import force_closure_baseline as old_baseline

        loaded = load_target("baselines.pairing:force_closure_baseline")
    from baselines.baseline_commands import register
    from baselines.pairing_baselines import force_closure_baseline

    assert old_register is register
    assert old_baseline is force_closure_baseline
    assert loaded is force_closure_baseline


def test_the_package_imports_no_heavy_library() -> None:
    """``import baselines`` (and so its finder of old paths) imports no numpy or torch."""
    code = "import sys, baselines\nprint(sorted({'numpy', 'torch', 'h5py'} & set(sys.modules)))\n"
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    assert out.strip() == "[]"
