"""Old import paths of :mod:`dg16m_env`, kept for one release after the package was laid out in
layers (0.2.0; see ``CHANGELOG.md``): importing one still works and raises a
:class:`DeprecationWarning` that names the new home.

Two kinds of redirect:

* :data:`MOVED_MODULES`: a module that moved whole (``dg16m_env.trial`` ->
  ``dg16m_env.physics.trial``) is the same module object under its old name, so reading,
  patching or reloading it through either name acts on the one module; a module that was cut in
  pieces (``dg16m_env.submission``) is a small module that looks each name up in its pieces, in
  order.
* :data:`MOVED_NAMES`: a name that left a module that still exists
  (``dg16m_env.envs.dual_grasp_lift.ScriptedLiftPolicy``) is found by that module's
  ``__getattr__`` (:func:`moved_names`).

Redirects are resolved by name with :func:`importlib.import_module` when they are used: this
table is not a dependency of the layers, and nothing in the package imports through it.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import types
import warnings
from collections.abc import Callable, Sequence
from typing import Any

REMOVED_IN = "0.3.0"
"""The release that drops the old paths."""

_P = "dg16m_env"

MOVED_MODULES: dict[str, tuple[str, ...]] = {
    # physics: MuJoCo scenes, the trial protocol and its engines, labels, replay
    f"{_P}.scene": (f"{_P}.physics.scene",),
    f"{_P}.simulator": (f"{_P}.physics.simulator",),
    f"{_P}.trial": (f"{_P}.physics.trial",),
    f"{_P}.trial_protocol": (f"{_P}.physics.trial_protocol", f"{_P}.physics.trial_measures"),
    f"{_P}.warp_trials": (f"{_P}.physics.warp_trials",),
    f"{_P}.warp_kernels": (f"{_P}.physics.warp_kernels",),
    f"{_P}.labels": (f"{_P}.physics.labels",),
    f"{_P}.replay": (f"{_P}.physics.replay",),
    f"{_P}.reseat": (f"{_P}.physics.reseat",),
    f"{_P}.gsr": (f"{_P}.physics.gsr_core",),
    f"{_P}.envs.cameras": (f"{_P}.physics.cameras",),
    f"{_P}.envs.lift_scene": (f"{_P}.physics.lift_scene",),
    # benchmark: the model, the file, sources, building, short names, reports, real objects
    f"{_P}.benchmark_report": (
        f"{_P}.benchmark.report",
        f"{_P}.benchmark.report_text",
        f"{_P}.benchmark.report_plot",
    ),
    f"{_P}.real_benchmark": (f"{_P}.benchmark.real",),
    f"{_P}.real_build_state": (f"{_P}.benchmark.real_build_state",),
    f"{_P}.evaluators.context": (f"{_P}.benchmark.ref",),
    # subjects: what gets scored
    f"{_P}.submission": (
        f"{_P}.subjects.submission",
        f"{_P}.subjects.submission_reader",
        f"{_P}.subjects.submission_writer",
    ),
    f"{_P}.predictor": (f"{_P}.subjects.predictor", f"{_P}.subjects.predictor_process"),
    f"{_P}.observation": (f"{_P}.subjects.observation",),
    # cli: the dg16m subcommands
    f"{_P}.benchmark_command": (f"{_P}.cli.benchmark",),
    f"{_P}.evaluate_command": (f"{_P}.cli.evaluate",),
    f"{_P}.sim_command": (f"{_P}.cli.sim",),
}
"""Old module name -> its new module(s); a name is looked up in them in order."""

MOVED_NAMES: dict[str, dict[str, str]] = {
    f"{_P}.envs.dual_grasp_lift": {
        "ScriptedLiftPolicy": f"{_P}.envs.lift_expert",
        "PREGRASP_DISTANCE": f"{_P}.envs.lift_expert",
        "REWARD_WEIGHTS": f"{_P}.envs.lift_reward",
    },
}
"""Module that still exists -> {name that left it: the module it went to}."""


def _warn(old: str, new: str, stacklevel: int) -> None:
    warnings.warn(
        f"{old} moved to {new}; the old path works until dg16m {REMOVED_IN}, then it is removed",
        DeprecationWarning,
        stacklevel=stacklevel,
    )


def moved_names(module: str) -> Callable[[str], Any]:
    """A module-level ``__getattr__`` for ``module`` that finds the names of
    :data:`MOVED_NAMES` ``[module]`` in their new modules, with a :class:`DeprecationWarning`."""
    moved = MOVED_NAMES[module]

    def __getattr__(name: str) -> Any:  # noqa: N807  (a module's __getattr__, PEP 562)
        target = moved.get(name)
        if target is None:
            raise AttributeError(f"module {module!r} has no attribute {name!r}")
        _warn(f"{module}.{name}", f"{target}.{name}", stacklevel=3)
        return getattr(importlib.import_module(target), name)

    return __getattr__


class _PiecesModule(types.ModuleType):
    """An old module that was cut in pieces: each attribute comes from the first piece that has
    it."""

    _pieces: Sequence[str]

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__"):
            raise AttributeError(name)
        for piece in self._pieces:
            module = importlib.import_module(piece)
            if hasattr(module, name):
                return getattr(module, name)
        raise AttributeError(
            f"module {self.__name__!r} has no attribute {name!r} (it moved to "
            f"{', '.join(self._pieces)}, which do not have it either)"
        )

    def __dir__(self) -> list[str]:
        names: set[str] = set()
        for piece in self._pieces:
            names.update(dir(importlib.import_module(piece)))
        return sorted(names)


class _MovedModuleLoader(importlib.abc.Loader):
    def __init__(self, old: str, new: tuple[str, ...]) -> None:
        self.old, self.new = old, new
        self._own_spec: importlib.machinery.ModuleSpec | None = None

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> types.ModuleType:
        # warnings skips importlib's own frames: stacklevel 3 is the line that imports the old name
        _warn(self.old, " and ".join(self.new), stacklevel=3)
        if len(self.new) == 1:
            moved = importlib.import_module(self.new[0])
            self._own_spec = moved.__spec__
            return moved
        module = _PiecesModule(self.old, f"The old home of {', '.join(self.new)} (deprecated).")
        module._pieces = self.new
        all_names: list[str] = []
        for piece in self.new:
            all_names += list(getattr(importlib.import_module(piece), "__all__", ()))
        if all_names:
            module.__all__ = all_names
        return module

    def exec_module(self, module: types.ModuleType) -> None:
        # importlib set the old name's spec on the module; a moved module keeps its own.
        if len(self.new) == 1:
            module.__spec__ = self._own_spec


class _MovedModuleFinder(importlib.abc.MetaPathFinder):
    """Finds the old names of :data:`MOVED_MODULES` (no file has them any more)."""

    def find_spec(
        self, fullname: str, path: Any = None, target: types.ModuleType | None = None
    ) -> importlib.machinery.ModuleSpec | None:
        new = MOVED_MODULES.get(fullname)
        if new is None:
            return None
        return importlib.machinery.ModuleSpec(fullname, _MovedModuleLoader(fullname, new))


def install() -> None:
    """Put the finder of the old module names on ``sys.meta_path`` (once)."""
    if not any(isinstance(finder, _MovedModuleFinder) for finder in sys.meta_path):
        sys.meta_path.append(_MovedModuleFinder())
