"""The old import paths of ``dataset_gen`` (before the kernel ``dg16m_core`` and the folders)
still work for one release and warn, with the mechanism of ``dg16m_core.compat`` (tested as
``tests/test_layout_compat.py`` tests ``dg16m_env``'s, with its ``fresh_import``)."""

from __future__ import annotations

import importlib
import subprocess
import sys
import warnings

import pytest
from test_layout_compat import fresh_import

import dataset_gen  # noqa: F401  (installs the finder of the old paths)
from dataset_gen._compat import MOVED_MODULES, RENAMED_MODULES
from dg16m_core.compat import REMOVED_IN


@pytest.mark.parametrize("old", sorted(MOVED_MODULES))
def test_an_old_dataset_gen_module_path_imports_and_warns(old: str) -> None:
    new = MOVED_MODULES[old]
    with pytest.warns(DeprecationWarning, match=rf"{old} moved to .*until dg16m {REMOVED_IN}"):
        module = fresh_import(old)
    pieces = [importlib.import_module(piece) for piece in new]
    if len(new) == 1:
        assert module is pieces[0]
        assert module.__name__ == new[0]
        return
    for piece in pieces:
        for name in [n for n in vars(piece) if not n.startswith("_")]:
            first = next(p for p in pieces if hasattr(p, name))
            assert getattr(module, name) is getattr(first, name), (old, name)


@pytest.mark.parametrize("old", sorted(RENAMED_MODULES))
def test_a_folder_that_took_a_module_name_finds_its_old_names(old: str) -> None:
    """``dataset_gen.objects.GraspObject`` (the old module's name) is found in
    ``dataset_gen.objects.grasp_object`` with a warning; a name nobody had is an
    AttributeError."""
    folder = importlib.import_module(old)
    target = importlib.import_module(RENAMED_MODULES[old])
    public = sorted(
        n for n in vars(target) if n[0].isupper() and n not in vars(folder) and n != "Any"
    )
    assert public, RENAMED_MODULES[old]
    with pytest.warns(DeprecationWarning, match=rf"{old}\.{public[0]} moved to"):
        value = getattr(folder, public[0])
    assert value is getattr(target, public[0])
    with pytest.raises(AttributeError, match="has no attribute 'no_such_name'"):
        _ = folder.no_such_name  # type: ignore[attr-defined]


def test_what_user_code_imports_today_still_works() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        from dataset_gen.errors import Dg16mError as OldError
        from dataset_gen.gripper import contacts_from_pose as old_contacts
        from dataset_gen.parameters import PAPER as OLD_PAPER

        from dataset_gen.objects import GraspObject as OldObject
        from dataset_gen.sources import ObjectSource as OldSource
    from dataset_gen.grasps.gripper import contacts_from_pose
    from dataset_gen.objects.grasp_object import GraspObject
    from dataset_gen.sources.object_source import ObjectSource
    from dg16m_core.errors import Dg16mError
    from dg16m_core.parameters import PAPER

    assert OldError is Dg16mError
    assert old_contacts is contacts_from_pose
    assert OldObject is GraspObject
    assert OLD_PAPER is PAPER
    assert OldSource is ObjectSource


def test_the_old_command_line_module_still_runs() -> None:
    """``from dataset_gen.cli import main`` (an old way to call the command line) warns and
    runs the kernel's command line."""
    old = subprocess.run(
        [
            sys.executable,
            "-W",
            "always::DeprecationWarning",
            "-c",
            "import sys; from dataset_gen.cli import main; sys.exit(main(['--version']))",
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    assert "dataset_gen.cli.main moved to dg16m_core.cli.main" in old.stderr
    assert old.stdout.startswith("dg16m ")


def test_the_package_imports_no_heavy_library() -> None:
    """``import dataset_gen`` (and so every old path's finder) imports no trimesh, h5py or numpy."""
    code = (
        "import sys, dataset_gen\n"
        "print(sorted({'trimesh', 'h5py', 'numpy', 'scipy'} & set(sys.modules)))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    assert out.strip() == "[]"
