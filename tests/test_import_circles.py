"""No import circles between the project's modules (DESIGN.md: dependencies point one way).

Imports are read with :mod:`ast`, function-level ones included (a lazy import that only hides a
circle is still a circle), so the check needs no heavy import and runs in well under a second.
An edge ``a -> b`` means module ``a`` names module ``b`` in an ``import`` statement anywhere in
its source; ``from package import name`` counts as an import of ``package.name`` when that is a
module, else of ``package``. The implicit import of a parent package's ``__init__`` is not an
edge (every submodule would otherwise depend on its package).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("dataset_gen", "dg16m_env", "baselines", "leaderboard")


def project_modules() -> dict[str, Path]:
    """Dotted module name -> source file, for every module of :data:`PACKAGES`."""
    modules: dict[str, Path] = {}
    for package in PACKAGES:
        for path in sorted((REPO / package).rglob("*.py")):
            parts = list(path.relative_to(REPO).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            modules[".".join(parts)] = path
    return modules


def imported_modules(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The project modules that module ``name`` (source ``path``) imports, at any depth of its
    source (module level, functions, ``TYPE_CHECKING`` blocks)."""
    is_package = path.name == "__init__.py"
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names if alias.name in modules)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".") if is_package else name.split(".")[:-1]
                base = base[: len(base) - (node.level - 1)]
                source = ".".join([*base, *([node.module] if node.module else [])])
            else:
                source = node.module or ""
            for alias in node.names:
                if f"{source}.{alias.name}" in modules:
                    found.add(f"{source}.{alias.name}")
                elif source in modules:
                    found.add(source)
    found.discard(name)
    return found


def import_graph() -> dict[str, set[str]]:
    """Module -> the project modules it imports."""
    modules = project_modules()
    return {name: imported_modules(name, path, modules) for name, path in modules.items()}


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan, iterative), each
    sorted; every import circle lies inside one of them."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return found


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    return import_graph()


def test_the_checker_sees_function_level_circles() -> None:
    """A circle closed only by a lazy import is found; a one-way chain is not a circle."""
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert circles({"a": {"b"}, "b": {"c"}, "c": set()}) == []
    source = "def f():\n    from baselines.commands import register\n"
    tree_imports = {
        node.module for node in ast.walk(ast.parse(source)) if isinstance(node, ast.ImportFrom)
    }
    assert tree_imports == {"baselines.commands"}


def test_no_import_circles_in_the_project(graph: dict[str, set[str]]) -> None:
    found = circles(graph)
    assert found == [], f"expected no import circles, found {found}"


def test_baselines_command_module_sits_above_what_it_calls(graph: dict[str, set[str]]) -> None:
    """``baselines.commands`` imports the modules it runs; none of them imports it back."""
    assert {"baselines.reference_submissions", "baselines.reproduce"} <= graph["baselines.commands"]
    importers = sorted(m for m, deps in graph.items() if "baselines.commands" in deps)
    assert importers == [], f"expected nothing to import baselines.commands, found {importers}"
    light = graph["baselines.submission_arguments"]
    assert not light & {"baselines.reference_submissions", "baselines.reproduce"}


def test_trial_engine_choice_sits_above_both_engines(graph: dict[str, set[str]]) -> None:
    """``dg16m_env.trial`` (the engine choice and the C path) imports the Warp engine and the
    protocol; the Warp engine imports the protocol, never the module that chooses it."""
    assert {"dg16m_env.warp_trials", "dg16m_env.trial_protocol"} <= graph["dg16m_env.trial"]
    assert "dg16m_env.trial" not in graph["dg16m_env.warp_trials"]
    assert "dg16m_env.trial_protocol" in graph["dg16m_env.warp_trials"]
    assert not graph["dg16m_env.trial_protocol"] & {"dg16m_env.trial", "dg16m_env.warp_trials"}


def test_trial_keeps_its_public_names() -> None:
    """Every public name of the protocol is importable from ``dg16m_env.trial`` and is the same
    object, and ``run_trials`` still takes the engine."""
    import inspect

    from dg16m_env import trial, trial_protocol

    for name in trial_protocol.__all__:
        assert getattr(trial, name) is getattr(trial_protocol, name), name
    assert "simulator" in inspect.signature(trial.run_trials).parameters
