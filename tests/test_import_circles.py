"""No import circles between the project's modules (DESIGN.md: dependencies point one way), the
packages depend on each other one way (:data:`PACKAGE_DEPENDENCIES`: the kernel ``dg16m_core``
under ``dataset_gen`` under ``dg16m_env`` under ``baselines`` and ``leaderboard``), and
``dg16m_env``'s and ``dataset_gen``'s imports follow their layers (:data:`LAYERS`,
:data:`DATASET_GEN_LAYERS`: each module imports only from its own layer and the layers below).

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
PACKAGES = ("dg16m_core", "dataset_gen", "dg16m_env", "baselines", "leaderboard")


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
    """``baselines.baseline_commands`` imports the modules it runs; none of them imports it
    back."""
    commands = "baselines.baseline_commands"
    assert {"baselines.reference_submissions", "baselines.reproduce"} <= graph[commands]
    importers = sorted(m for m, deps in graph.items() if commands in deps)
    assert importers == [], f"expected nothing to import {commands}, found {importers}"
    light = graph["baselines.submission_arguments"]
    assert not light & {"baselines.reference_submissions", "baselines.reproduce"}


LAYERS: tuple[tuple[str, ...], ...] = (
    ("dg16m_env.rates",),
    ("dg16m_env.physics",),
    ("dg16m_env.benchmark",),
    ("dg16m_env.subjects",),
    ("dg16m_env.training",),
    ("dg16m_env.evaluators",),
    ("dg16m_env.envs",),
    ("dg16m_env.cli",),
)
"""``dg16m_env``'s layers, bottom first: module-name prefixes (see ``dg16m_env/__init__.py``)."""

#: Modules outside the layers: the package's ``__init__`` (it registers envs once Gymnasium is) and
#: the table of old import paths (it imports nothing of the package by an import statement).
UNLAYERED = {"dg16m_env", "dg16m_env._compat"}


def layer_of(module: str, layers: tuple[tuple[str, ...], ...] = LAYERS) -> int | None:
    """The index in ``layers`` of a module, ``None`` for a module of no layer."""
    for index, prefixes in enumerate(layers):
        if any(module == p or module.startswith(p + ".") for p in prefixes):
            return index
    return None


def upward_imports(
    graph: dict[str, set[str]], layers: tuple[tuple[str, ...], ...] = LAYERS
) -> list[str]:
    """Every import of a module of ``layers`` from a higher layer, as
    ``"a (layer) -> b (layer)"``."""
    found = []
    for module, deps in sorted(graph.items()):
        here = layer_of(module, layers)
        if here is None:
            continue
        for dep in sorted(deps):
            there = layer_of(dep, layers)
            if there is not None and there > here:
                found.append(f"{module} ({layers[here][0]}) -> {dep} ({layers[there][0]})")
    return found


def test_the_layer_check_sees_an_upward_import() -> None:
    """An import from a higher layer is reported, one from a lower layer or the same is not."""
    graph = {
        "dg16m_env.physics.scene": {"dg16m_env.benchmark.file"},
        "dg16m_env.benchmark.file": {"dg16m_env.physics.scene", "dg16m_env.benchmark.model"},
        "dg16m_env.benchmark.model": set(),
        "dg16m_env.cli.evaluate": {"dg16m_env.envs.common"},
    }
    assert upward_imports(graph) == [
        "dg16m_env.physics.scene (dg16m_env.physics) -> dg16m_env.benchmark.file "
        "(dg16m_env.benchmark)"
    ]


def test_every_dg16m_env_module_sits_in_a_layer(graph: dict[str, set[str]]) -> None:
    """A new module goes where its layer is: none sits outside the layers (besides
    :data:`UNLAYERED`), and the package's top holds only the layers, rates and the old-path
    table."""
    outside = sorted(
        m for m in graph if m.startswith("dg16m_env") and layer_of(m) is None and m not in UNLAYERED
    )
    assert outside == [], f"expected every dg16m_env module in a layer, found {outside}"


def test_dg16m_env_imports_point_down_the_layers(graph: dict[str, set[str]]) -> None:
    found = upward_imports(graph)
    assert found == [], f"expected no import against dg16m_env's layer order, found {found}"


def test_the_table_of_old_paths_imports_nothing_of_the_package(
    graph: dict[str, set[str]],
) -> None:
    """``dg16m_env._compat`` resolves old paths by name when they are used (with the kernel's
    mechanism); it is not a dependency of any layer, and no layer imports through it."""
    assert graph["dg16m_env._compat"] == {"dg16m_core.compat"}
    users = sorted(m for m, deps in graph.items() if "dg16m_env._compat" in deps)
    assert users == ["dg16m_env"], users


#: About 800 lines (issue 42's target, issue 53 for every package), with room for a module whose
#: documentation is long.
MAX_MODULE_LINES = 850

#: About 120 lines (issue 53): a longer function is cut where its steps part.
MAX_FUNCTION_LINES = 125


def test_no_library_module_is_over_about_800_lines() -> None:
    """The long modules were cut where their concepts part; none grows back past
    :data:`MAX_MODULE_LINES`, in any package."""
    long = {
        str(path.relative_to(REPO)): n
        for package in PACKAGES
        for path in sorted((REPO / package).rglob("*.py"))
        if (n := len(path.read_text(encoding="utf-8").splitlines())) > MAX_MODULE_LINES
    }
    assert long == {}, f"expected no library module over {MAX_MODULE_LINES} lines, found {long}"


def long_functions(source: str, limit: int) -> list[tuple[str, int]]:
    """The functions and methods of ``source`` over ``limit`` lines (decorators and docstring
    included), as ``(qualified name, lines)``."""
    found: list[tuple[str, int]] = []

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
                name = f"{prefix}{child.name}"
                if not isinstance(child, ast.ClassDef):
                    start = min([child.lineno, *(d.lineno for d in child.decorator_list)])
                    if (n := child.end_lineno - start + 1) > limit:
                        found.append((name, n))
                visit(child, name + ".")

    visit(ast.parse(source), "")
    return found


def test_the_function_checker_counts_lines() -> None:
    source = "class A:\n    def f(self):\n" + "        x = 1\n" * 5 + "def g():\n    pass\n"
    assert long_functions(source, 5) == [("A.f", 6)]
    assert long_functions(source, 6) == []


def test_no_library_function_is_over_about_120_lines() -> None:
    """No function of a library package runs past :data:`MAX_FUNCTION_LINES` (tests, bench and
    scripts are not library code)."""
    long = {
        f"{path.relative_to(REPO)}:{name}": n
        for package in PACKAGES
        for path in sorted((REPO / package).rglob("*.py"))
        for name, n in long_functions(path.read_text(encoding="utf-8"), MAX_FUNCTION_LINES)
    }
    assert long == {}, f"expected no function over {MAX_FUNCTION_LINES} lines, found {long}"


def test_trial_engine_choice_sits_above_both_engines(graph: dict[str, set[str]]) -> None:
    """``dg16m_env.physics.trial`` (the engine choice and the C path) imports the Warp engine and
    the protocol; the Warp engine imports the protocol, never the module that chooses it."""
    trial, warp = "dg16m_env.physics.trial", "dg16m_env.physics.warp_trials"
    protocol = "dg16m_env.physics.trial_protocol"
    assert {warp, protocol} <= graph[trial]
    assert trial not in graph[warp]
    assert protocol in graph[warp]
    assert not graph[protocol] & {trial, warp}


def test_trial_keeps_its_public_names() -> None:
    """Every public name of the protocol and its measures is importable from
    ``dg16m_env.physics.trial`` and is the same object, and ``run_trials`` still takes the
    engine."""
    import inspect

    from dg16m_env.physics import trial, trial_measures, trial_protocol

    for module in (trial_protocol, trial_measures):
        for name in module.__all__:
            assert getattr(trial, name) is getattr(module, name), name
    assert "simulator" in inspect.signature(trial.run_trials).parameters


PACKAGE_DEPENDENCIES: dict[str, set[str]] = {
    "dg16m_core": set(),
    "dataset_gen": {"dg16m_core"},
    "dg16m_env": {"dg16m_core", "dataset_gen"},
    "baselines": {"dg16m_core", "dataset_gen", "dg16m_env"},
    "leaderboard": {"dg16m_core", "dataset_gen", "dg16m_env"},
}
"""Package -> the project packages it may import (DESIGN.md: dependencies point one way)."""


def test_packages_import_each_other_one_way(graph: dict[str, set[str]]) -> None:
    """The kernel imports no project package; ``dataset_gen`` only the kernel; nothing imports
    ``baselines`` or ``leaderboard`` but themselves."""
    found = sorted(
        f"{module} -> {dep}"
        for module, deps in graph.items()
        for dep in deps
        if (a := module.split(".")[0]) != (b := dep.split(".")[0])
        and b not in PACKAGE_DEPENDENCIES[a]
    )
    assert found == [], f"expected imports along {PACKAGE_DEPENDENCIES}, found {found}"


DATASET_GEN_LAYERS: tuple[tuple[str, ...], ...] = (
    ("dataset_gen.objects",),
    ("dataset_gen.io", "dataset_gen.force_closure"),
    ("dataset_gen.grasps",),
    ("dataset_gen.sources",),
    ("dataset_gen.pipeline",),
    ("dataset_gen.real",),
    ("dataset_gen.collection",),
    ("dataset_gen.cli",),
)
"""``dataset_gen``'s floors, bottom first (see ``dataset_gen/__init__.py``); the kernel
``dg16m_core`` is under all of them."""

#: The package's ``__init__`` (it installs the old paths) and the table of old paths.
DATASET_GEN_UNLAYERED = {"dataset_gen", "dataset_gen._compat"}


def test_every_dataset_gen_module_sits_in_a_folder(graph: dict[str, set[str]]) -> None:
    """``dataset_gen``'s top holds only its folders, the package's face and the old-path table."""
    outside = sorted(
        m
        for m in graph
        if m.split(".")[0] == "dataset_gen"
        and layer_of(m, DATASET_GEN_LAYERS) is None
        and m not in DATASET_GEN_UNLAYERED
    )
    assert outside == [], f"expected every dataset_gen module in a folder, found {outside}"


def test_dataset_gen_imports_point_down_its_floors(graph: dict[str, set[str]]) -> None:
    found = upward_imports(graph, DATASET_GEN_LAYERS)
    assert found == [], f"expected no import against dataset_gen's floors, found {found}"


def test_the_kernel_and_dataset_gen_old_path_tables(graph: dict[str, set[str]]) -> None:
    """``dataset_gen._compat`` uses only the kernel's mechanism, and only the folders that took
    an old module's name (and the package's face) use it."""
    assert graph["dataset_gen._compat"] == {"dg16m_core.compat"}
    users = sorted(m for m, deps in graph.items() if "dataset_gen._compat" in deps)
    assert users == [
        "dataset_gen",
        "dataset_gen.cli",
        "dataset_gen.objects",
        "dataset_gen.sources",
    ], users
    kernel_users = sorted(m for m, deps in graph.items() if "dg16m_core.compat" in deps)
    assert {"dataset_gen._compat", "dg16m_env._compat"} <= set(kernel_users), kernel_users
    assert all(m.endswith("._compat") for m in kernel_users), kernel_users
