"""Old import paths kept for one release after a module moved: the mechanism, written once.

Each package that moved modules keeps its own table (``dg16m_env._compat``,
``dataset_gen._compat``) and installs it with :func:`install`; importing an old path still works
and raises a :class:`DeprecationWarning` that names the new home.

Three kinds of redirect:

* a module that moved whole (``dg16m_env.trial`` -> ``dg16m_env.physics.trial``) is the same
  module object under its old name, so reading, patching or reloading it through either name
  acts on the one module;
* a module that was cut in pieces (``dg16m_env.submission``) is a small module that looks each
  name up in its pieces, in order;
* the names of a module whose name is now a folder's (``dataset_gen.objects`` is the folder of
  object modules; its old names live in ``dataset_gen.objects.grasp_object``) are found by the
  folder's ``__getattr__`` (:func:`moved_names`).

Redirects are resolved by name with :func:`importlib.import_module` when they are used: a table
is not a dependency of the layers, and nothing in the project imports through it. Standard
library only.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import types
import warnings
from collections.abc import Callable, Mapping, Sequence
from typing import Any

REMOVED_IN = "0.3.0"
"""The release that drops the old paths."""


def warn_moved(old: str, new: str, stacklevel: int) -> None:
    """The :class:`DeprecationWarning` of an old path ``old`` whose new home is ``new``."""
    warnings.warn(
        f"{old} moved to {new}; the old path works until dg16m {REMOVED_IN}, then it is removed",
        DeprecationWarning,
        stacklevel=stacklevel,
    )


def moved_names(module: str, target: str) -> Callable[[str], Any]:
    """A module-level ``__getattr__`` (PEP 562) for ``module``, a folder that took the name of an
    old module whose names all went to ``target``: each of them is found there, with a
    :class:`DeprecationWarning`."""

    def __getattr__(name: str) -> Any:  # noqa: N807  (a module's __getattr__, PEP 562)
        if name.startswith("__") or not hasattr(importlib.import_module(target), name):
            raise AttributeError(f"module {module!r} has no attribute {name!r}")
        warn_moved(f"{module}.{name}", f"{target}.{name}", stacklevel=3)
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
        warn_moved(self.old, " and ".join(self.new), stacklevel=3)
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


class MovedModuleFinder(importlib.abc.MetaPathFinder):
    """Finds the old names of one table of moved modules (no file has them any more)."""

    def __init__(self, moved_modules: Mapping[str, tuple[str, ...]]) -> None:
        self.moved_modules = moved_modules

    def find_spec(
        self, fullname: str, path: Any = None, target: types.ModuleType | None = None
    ) -> importlib.machinery.ModuleSpec | None:
        new = self.moved_modules.get(fullname)
        if new is None:
            return None
        return importlib.machinery.ModuleSpec(fullname, _MovedModuleLoader(fullname, new))


def install(moved_modules: Mapping[str, tuple[str, ...]]) -> None:
    """Put a finder of the old module names of ``moved_modules`` (old name -> its new module(s);
    a name is looked up in them in order) on ``sys.meta_path``, once per table."""
    if not any(
        isinstance(finder, MovedModuleFinder) and finder.moved_modules is moved_modules
        for finder in sys.meta_path
    ):
        sys.meta_path.append(MovedModuleFinder(moved_modules))
