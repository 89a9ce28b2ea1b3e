"""The old import paths of ``dg16m_env`` (before its layered layout) still work for one release and
warn, and the benchmark package's names resolve to the modules that define them.

Each old module name is dropped from ``sys.modules`` before it is imported, so the warning is
seen on every run of the test (an import is cached after the first)."""

from __future__ import annotations

import importlib
import importlib.util
import subprocess
import sys
import warnings
from importlib import metadata

import pytest

import dg16m_env  # noqa: F401  (installs the finder of the old paths)
from dg16m_env._compat import MOVED_MODULES, REMOVED_IN


def fresh_import(name: str) -> object:
    sys.modules.pop(name, None)
    parent, _, leaf = name.rpartition(".")
    if parent in sys.modules and leaf in vars(sys.modules[parent]):
        delattr(sys.modules[parent], leaf)
    return importlib.import_module(name)


@pytest.mark.parametrize("old", sorted(MOVED_MODULES))
def test_an_old_module_path_imports_and_warns(old: str) -> None:
    new = MOVED_MODULES[old]
    if old.endswith("warp_kernels") and importlib.util.find_spec("warp") is None:
        pytest.skip("the Warp kernels need the optional warp extra: pip install -e '.[warp]'")
    with pytest.warns(DeprecationWarning, match=rf"{old} moved to .*until dg16m {REMOVED_IN}"):
        module = fresh_import(old)
    pieces = [importlib.import_module(piece) for piece in new]
    if len(new) == 1:
        # the same module object: reading or patching it through either name acts on one module
        assert module is pieces[0]
        assert module.__spec__.name == new[0]
        assert module.__name__ == new[0]
        return
    for piece in pieces:
        for name in getattr(piece, "__all__", [n for n in vars(piece) if not n.startswith("_")]):
            first = next(p for p in pieces if hasattr(p, name))
            assert getattr(module, name) is getattr(first, name), (old, name)
    with pytest.raises(AttributeError, match="which do not have it either"):
        _ = module.no_such_name  # type: ignore[attr-defined]


def test_an_old_path_warns_at_the_importing_line() -> None:
    """The warning points at the line that imports the old name (not at importlib)."""
    sys.modules.pop("dg16m_env.scene", None)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        exec("import dg16m_env.scene", {"__name__": "importer"})
    assert [w.filename for w in caught if issubclass(w.category, DeprecationWarning)] == [
        "<string>"
    ]


def test_from_imports_of_old_paths_work() -> None:
    """What user code imports today: a moved module's names, a cut module's names, a moved
    name of the Lift module."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        from dg16m_env.envs.dual_grasp_lift import ScriptedLiftPolicy as Old
        from dg16m_env.evaluators.context import BenchmarkRef as OldRef
        from dg16m_env.submission import read_submission, write_submission
        from dg16m_env.trial import TrialStatus, judge, run_trials
    from dg16m_env.benchmark.ref import BenchmarkRef
    from dg16m_env.envs.lift.experts import ScriptedLiftPolicy
    from dg16m_env.physics import trial, trial_measures, trial_protocol
    from dg16m_env.subjects import submission_reader, submission_writer

    assert Old is ScriptedLiftPolicy
    assert OldRef is BenchmarkRef
    assert read_submission is submission_reader.read_submission
    assert write_submission is submission_writer.write_submission
    assert TrialStatus is trial_protocol.TrialStatus
    assert judge is trial_measures.judge
    assert run_trials is trial.run_trials


def test_the_benchmark_package_names_resolve_without_a_warning() -> None:
    """``from dg16m_env.benchmark import read_benchmark`` (the former module's names and
    ``BenchmarkRef``) is the package's API: no warning, the defining module's object."""
    import dg16m_env.benchmark as package

    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        for name, module in package._EXPORTS.items():
            defining = importlib.import_module(f"dg16m_env.benchmark.{module}")
            assert getattr(package, name) is getattr(defining, name), name
    assert set(package.__all__) == set(package._EXPORTS)
    with pytest.raises(AttributeError, match="has no attribute 'load_everything'"):
        _ = package.load_everything  # type: ignore[attr-defined]


def test_reading_a_benchmark_does_not_import_the_builder() -> None:
    """The file's reader and the builder are apart: reading the shipped benchmark imports
    neither the build module nor the report, in a fresh interpreter."""
    code = (
        "import sys\n"
        "from dg16m_env.benchmark import EMBEDDED_BENCHMARK, read_benchmark\n"
        "read_benchmark(EMBEDDED_BENCHMARK)\n"
        "print(sorted(m for m in sys.modules if m.startswith('dg16m_env.benchmark.')))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    loaded = eval(out)  # our own print of a list of strings
    assert "dg16m_env.benchmark.file" in loaded
    assert not {"dg16m_env.benchmark.build", "dg16m_env.benchmark.report"} & set(loaded), loaded


def test_the_commands_and_environments_keep_their_entry_points() -> None:
    """The ``dg16m`` subcommands of dg16m_env load from the cli layer, and the environments'
    entry points are unchanged (``dg16m_env.envs.<module>:<Env>``)."""
    import gymnasium

    commands = {
        ep.name: ep.value
        for ep in metadata.entry_points(group="dg16m.commands")
        if ep.name.startswith("dg16m_env")
    }
    assert commands == {
        f"dg16m_env.cli.{name}": f"dg16m_env.cli.{name}:register"
        for name in ("benchmark", "dataset", "demos", "evaluate", "sim")
    }
    for ep in metadata.entry_points(group="dg16m.commands"):
        if ep.name.startswith("dg16m_env"):
            assert callable(ep.load())
    assert gymnasium.spec("dg16m_env/DualGraspLift-v0").entry_point == (
        "dg16m_env.envs.lift.v0:DualGraspLiftEnv"
    )
