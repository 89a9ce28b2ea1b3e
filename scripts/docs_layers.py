"""Draw ``dg16m_env``'s layers and ``dataset_gen``'s floors (on the kernel ``dg16m_core``) with
the imports between them into ``docs/_static/pictures/layers.png`` and
``docs/_static/pictures/dataset_gen_layers.png`` (the user guide's *Layout* section shows them).

The pictures are made from the code, not by hand: the layers are
``tests/test_import_circles.py``'s :data:`LAYERS` and :data:`DATASET_GEN_LAYERS` and the imports
are that test's graph (read with :mod:`ast`, function-level imports included). Each layer is a box
with its modules; each box lists the layers it imports from, with how many module-to-module
imports each stands for; a layer that imported from above would be drawn red (the test fails on
it).

Usage::

    .venv/bin/python scripts/docs_layers.py [--out FOLDER]
"""

from __future__ import annotations

import argparse
import importlib.util
import textwrap
from collections import Counter
from pathlib import Path
from types import ModuleType

from matplotlib.figure import Figure
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "_static" / "pictures"


def load_layer_test() -> ModuleType:
    """``tests/test_import_circles.py`` as a module (its graph and layers)."""
    path = ROOT / "tests" / "test_import_circles.py"
    spec = importlib.util.spec_from_file_location("test_import_circles", path)
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


Layers = tuple[tuple[str, ...], ...]


def layer_contents(
    checker: ModuleType, layers: Layers
) -> tuple[list[list[str]], Counter[tuple[int, int]]]:
    """Per layer (bottom first) its module names without the layer's prefix; and the number of
    module imports from layer a to layer b, keyed (a, b) with a != b."""
    graph = checker.import_graph()
    modules: list[list[str]] = [[] for _ in layers]
    edges: Counter[tuple[int, int]] = Counter()
    for module, deps in graph.items():
        here = checker.layer_of(module, layers)
        if here is None:
            continue
        prefix = next(p for p in layers[here] if module == p or module.startswith(p + "."))
        short = module[len(prefix) + 1 :] if module != prefix else "__init__"
        if len(layers[here]) > 1 and short != "__init__":
            short = f"{prefix.rsplit('.', 1)[-1]}.{short}"
        modules[here].append(short or "__init__")
        for dep in deps:
            there = checker.layer_of(dep, layers)
            if there is not None and there != here:
                edges[here, there] += 1
    return [sorted(m) for m in modules], edges


def draw(checker: ModuleType, layers: Layers, package: str) -> Figure:
    """The picture of ``layers`` (bottom first); ``package``'s prefix is left out of the short
    names in the "imports from" lists."""
    modules, edges = layer_contents(checker, layers)
    n = len(modules)
    fig = Figure(figsize=(9.0, 0.9 * n + 0.3), dpi=110)
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_xlim(0, 10)
    ax.set_ylim(-0.1, n * 1.0)
    ax.axis("off")
    box_x, box_w, height = 0.3, 9.4, 0.78
    short = [" + ".join(p.removeprefix(package + ".") for p in layers[i]) for i in range(n)]
    for index, names in enumerate(modules):
        y = index * 1.0
        upward = [b for (a, b) in edges if a == index and b > index]
        ax.add_patch(
            FancyBboxPatch(
                (box_x, y),
                box_w,
                height,
                boxstyle="round,pad=0.02",
                facecolor="#fbe9e7" if upward else ("#eef3fb" if index % 2 else "#f7f7f2"),
                edgecolor="#4a5d7e",
            )
        )
        ax.text(
            box_x + 0.12,
            y + height - 0.17,
            " + ".join(layers[index]),
            fontsize=10,
            weight="bold",
            va="center",
        )
        below = sorted(((b, c) for (a, b), c in edges.items() if a == index), reverse=True)
        if below:
            text = "imports from: " + ", ".join(f"{short[b]} ({c})" for b, c in below)
            ax.text(
                box_x + box_w - 0.12,
                y + height - 0.17,
                text,
                fontsize=7.5,
                va="center",
                ha="right",
                color="#c0392b" if upward else "#4a5d7e",
            )
        listed = ", ".join(m for m in names if m != "__init__") or "(a module, not a folder)"
        lines = textwrap.wrap(listed, 150)
        ax.text(
            box_x + 0.12,
            y + (0.25 if len(lines) < 3 else 0.29),
            "\n".join(lines[:3]),
            fontsize=6.8 if len(lines) < 3 else 6.3,
            va="center",
            color="#333333",
            linespacing=1.4 if len(lines) < 3 else 1.25,
        )
        if index > 0:
            ax.add_patch(
                FancyArrowPatch(
                    (5.0, y - 0.0),
                    (5.0, y - 0.2),
                    arrowstyle="-|>",
                    mutation_scale=9,
                    color="#7a869a",
                )
            )
    return fig


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=OUT, help="folder of the pictures")
    args = parser.parse_args()
    checker = load_layer_test()
    pictures = {
        "layers.png": (checker.LAYERS, "dg16m_env"),
        "dataset_gen_layers.png": ((("dg16m_core",), *checker.DATASET_GEN_LAYERS), "dataset_gen"),
    }
    args.out.mkdir(parents=True, exist_ok=True)
    for name, (layers, package) in pictures.items():
        fig = draw(checker, layers, package)
        path = args.out / name
        tmp = path.with_suffix(".tmp.png")
        fig.savefig(tmp)
        tmp.replace(path)
        print(f"wrote {path} ({path.stat().st_size // 1024} KiB)")


if __name__ == "__main__":
    main()
