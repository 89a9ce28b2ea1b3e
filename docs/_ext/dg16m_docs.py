"""Sphinx extension of the dg16m documentation: pages generated from the code at build time.

* ``environments/``: one page per registered Gymnasium environment (Gymnasium's convention):
  a summary table from its registration and an instance (spaces, step limit, render modes,
  the ``gym.make`` line), its picture, its constructor keyword arguments (from the
  signature) and its documentation sections (Description, Action Space, ..., Version History)
  from its docstring, so the pages cannot drift from the code.
* ``api/``: one page per module of ``dg16m_core``, ``dataset_gen``, ``dg16m_env``,
  ``baselines`` and ``leaderboard`` (``automodule``), grouped per package.
* ``cli.md``: every ``dg16m`` command's ``--help``, from the parser itself.

Generated files are written only when their text changes (so Sphinx rebuilds only what
changed) and are not committed (``docs/.gitignore``). Docstrings that mark their sections with
Markdown headings (``## Description``, Gymnasium's convention) get those lines turned into
rubrics for autodoc.
"""

from __future__ import annotations

import argparse
import ast
import importlib
import inspect
import os
import pkgutil
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from docutils import nodes
from sphinx.application import Sphinx
from sphinx.util import logging
from sphinx.util.docutils import SphinxDirective

LOGGER = logging.getLogger(__name__)

PACKAGES = ("dg16m_core", "dataset_gen", "dg16m_env", "baselines", "leaderboard")
PACKAGE_SUMMARIES = {
    "dg16m_core": "the kernel every package may import: errors, checks, atomic writes, hashing, "
    "JSON values, budgets, stopping, the command line's plumbing, the paper's parameters, "
    "figures, old import paths",
    "dataset_gen": "the offline generator in folders: objects, grasps (grippers, sampling, "
    "pairing), force closure, file formats, sources, the pipeline, real meshes, its commands "
    "(no MuJoCo, no torch)",
    "dg16m_env": "the MuJoCo scene and trial protocol, the benchmark, submissions, evaluators "
    "and the Gymnasium environments",
    "baselines": "pairing baselines, reference submissions, classifiers, stable-baselines3 "
    "scripts, the demo and ``dg16m reproduce``",
    "leaderboard": "the results store, queue and workers, HTTP service, page and command line",
}

#: Environment name -> (picture under ``_static/pictures/``, its caption). The pictures are made
#: by ``scripts/docs_pictures.py``.
PICTURES = {
    "DualGraspPose-v0": (
        "pose_trial.gif",
        "One trial of the benchmark's protocol at a force-closure-passing dual grasp of "
        "``table-1000000`` (row 0 of the shipped benchmark): close, gravity, then the twelve "
        "pushes and twists; it holds (``dg16m sim replay --row 0 --out pose_trial.gif``).",
    ),
    "DualGraspSelect-v0": (
        "select_trial.png",
        "A poor pick: a random candidate of the same table (row 61) holds under gravity but "
        "slips out in the ``force-z`` push (``dg16m sim replay --row 61 --out "
        "select_trial.png``).",
    ),
    "DualGraspLift-v0": (
        "lift_episode.gif",
        # Captions are MyST Markdown (the figure's body): roles are written {role}`target`.
        "An episode of the scripted policy ({py:class}`~dg16m_env.envs.lift.experts."
        "ScriptedLiftPolicy`) with a benchmark target grasp on ``tub-1000013``, seed 0: the "
        "hands reach, close, lift the tub 10 cm and hold it for 1 s.",
    ),
    "DualGraspLift-v1": (
        "lift_episode.gif",
        "The task v1 keeps from v0 (the same physics, actions and success rule): the v0 "
        "episode of the scripted policy on ``tub-1000013``, seed 0, which reaches, closes, "
        "lifts the tub 10 cm and holds it for 1 s.",
    ),
    "DualGraspLift-v2": (
        "lift_v2_episode.gif",
        "An episode of DualGraspLift-v2 driven by the expert that ``dg16m demos collect`` "
        "records ({py:class}`~dg16m_env.envs.lift.experts.FeedbackLiftExpert`) with a "
        "benchmark target grasp on ``tub-1000013``, seed 0: the hands reach the "
        "target grasp on the rim, close, lift the tub 10 cm and hold it for 1 s (success "
        "after 81 steps). DualGraspLift-v3 with the same seed gives the same episode, step "
        "for step.",
    ),
    "DualGraspLift-v3": (
        "lift_v2_episode.gif",
        "An episode of DualGraspLift-v3 driven by the expert that ``dg16m demos collect`` "
        "records ({py:class}`~dg16m_env.envs.lift.experts.FeedbackLiftExpert`) with a "
        "benchmark target grasp on ``tub-1000013``, seed 0: the hands reach the "
        "target grasp on the rim, close, lift the tub 10 cm and hold it for 1 s, both hands "
        "grasping when success is credited (after 81 steps). Drawn on DualGraspLift-v2, "
        "which gives the same episode step for step (v3 changes only when success is "
        "credited; ``scripts/docs_pictures.py`` checks the two runs are equal).",
    ),
}

#: Display widths of pictures shown smaller than the content column (their own size).
PICTURE_WIDTHS = {
    "pose_trial.gif": "400px",
    "lift_episode.gif": "400px",
    "lift_v2_episode.gif": "400px",
}

HEADING = re.compile(r"^(#{2,4}) (\S.*)$")
UNDERLINE = re.compile(r"^([-=~^])\1{2,}$")


# -------------------------------------------------------------------------------------------
# Writing generated files
# -------------------------------------------------------------------------------------------


def write_if_changed(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` unless it already holds exactly that."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.exists() and path.read_text(encoding="utf-8") == text:
        return
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(path)


def remove_stale(folder: Path, keep: set[str]) -> None:
    """Remove generated pages of ``folder`` that are not in ``keep`` (a module or an
    environment that is gone)."""
    for path in [*folder.glob("*.md"), *folder.glob("*.rst")]:
        if path.name not in keep:
            path.unlink()


def fence(body: str, directive: str, argument: str = "", options: dict[str, str] | None = None):
    """A MyST directive block around ``body`` with a fence longer than any inside it."""
    ticks = "`" * max([3, *(len(m) + 1 for m in re.findall(r"`{3,}", body))])
    lines = [f"{ticks}{{{directive}}}{' ' + argument if argument else ''}"]
    lines += [f":{key}: {value}".rstrip() for key, value in (options or {}).items()]
    return "\n".join([*lines, body.rstrip("\n"), ticks, ""])


# -------------------------------------------------------------------------------------------
# Docstring sections
# -------------------------------------------------------------------------------------------


@dataclass
class Section:
    """One titled part of a docstring; ``body`` is reStructuredText."""

    title: str
    body: str


def split_docstring(doc: str) -> tuple[str, list[Section]]:
    """``(preamble, sections)`` of a docstring whose sections are marked either with Markdown
    headings (``## Title``) or with reStructuredText underlines (``Title`` over ``-----``)."""
    lines = inspect.cleandoc(doc).splitlines()
    preamble: list[str] = []
    sections: list[Section] = []
    current = preamble
    i = 0
    while i < len(lines):
        line = lines[i]
        heading = HEADING.match(line)
        underlined = (
            i + 1 < len(lines)
            and line.strip()
            and UNDERLINE.match(lines[i + 1].strip())
            and len(lines[i + 1].strip()) >= len(line.strip())
        )
        if heading or underlined:
            title = heading.group(2) if heading else line.strip()
            sections.append(Section(title, ""))
            current = []
            sections[-1].body = current  # type: ignore[assignment]
            i += 1 if heading else 2
            continue
        current.append(line)
        i += 1
    for section in sections:
        section.body = "\n".join(section.body).strip("\n")  # type: ignore[arg-type]
    return "\n".join(preamble).strip("\n"), sections


BORDER = re.compile(r"^( *)(=+(?: +=+)+) *$")


def repair_simple_tables(lines: list[str]) -> list[str]:
    """Widen the columns of reStructuredText simple tables whose text runs into the margin
    between two columns (docutils refuses those as "Malformed table"); other tables and
    text are returned unchanged."""
    out: list[str] = []
    i = 0
    while i < len(lines):
        match = BORDER.match(lines[i])
        if not match:
            out.append(lines[i])
            i += 1
            continue
        indent = len(match.group(1))
        runs = [(m.start() + indent, m.end() + indent) for m in re.finditer(r"=+", match.group(2))]
        end, borders = i + 1, 1
        while end < len(lines) and lines[end].strip():
            if BORDER.match(lines[end]):
                borders += 1
            end += 1
        table = lines[i:end]
        if borders < 2 or not _overflows(table, runs):
            out += table
            i = end
            continue
        starts = [start for start, _ in runs]
        rows = []
        for line in table:
            if BORDER.match(line):
                rows.append(None)
                continue
            bounds = [*starts[1:], None]
            rows.append([line[a:b].rstrip() for a, b in zip(starts, bounds, strict=True)])
        widths = [
            max([stop - start, *(len(row[j]) for row in rows if row)])
            for j, (start, stop) in enumerate(runs)
        ]
        pad = " " * indent
        for row in rows:
            if row is None:
                out.append(pad + "  ".join("=" * w for w in widths))
            else:
                cells = [cell.strip().ljust(w) for cell, w in zip(row, widths, strict=True)]
                # keep a cell's own indentation (continuation lines) beyond the column start
                cells = [
                    (cell[: len(cell) - len(cell.lstrip())] + c.strip()).ljust(w)
                    for cell, c, w in zip(row, cells, widths, strict=True)
                ]
                out.append((pad + "  ".join(cells)).rstrip())
        i = end
    return out


def _overflows(table: list[str], runs: list[tuple[int, int]]) -> bool:
    """Whether any row has text in a margin between two columns."""
    gaps = [(stop, runs[j + 1][0]) for j, (_, stop) in enumerate(runs[:-1])]
    for line in table:
        if BORDER.match(line):
            continue
        if any(line[a:b].strip() for a, b in gaps):
            return True
    return False


#: Docstrings that docutils cannot parse as they are, by the object's full name: (text, fix).
#: Each is a defect of the source docstring (fix it there, then drop the entry here; a fix that
#: no longer applies is reported at build time).
DOCSTRING_FIXES: dict[str, list[tuple[str, str]]] = {
    # "*F" opens an emphasis that never closes
    "baselines.grasp_geometry.gather_points": [("*F", "\\*F"), ("*I", "\\*I")],
    # "|v|" is a substitution reference in reStructuredText
    "baselines.da2_labels": [
        ("(``m`` the contacts' centroid, |v| >= 1)", "(``m`` the contacts' centroid, ``|v| >= 1``)")
    ],
    "dataset_gen.grasps.pairing.SAT_EPSILON": [("Added to |R| in", "Added to ``|R|`` in")],
    # an indented command block after a list item, without "::"
    "baselines.train_classifier": [
        ("   results.\n\n    .venv/bin/dg16m", "   results.\n\nCommands::\n\n    .venv/bin/dg16m")
    ],
}


def plain_signature_of_instances(
    app: Sphinx,
    what: str,
    name: str,
    obj: Any,
    options: Any,
    signature: str | None,
    return_annotation: str | None,
) -> tuple[str | None, str | None] | None:
    """``autodoc-process-signature`` (before sphinx-autodoc-typehints): keep autodoc's own
    signature of a callable instance (``random_baseline = PairingBaseline("random")``), which
    sphinx-autodoc-typehints fails on."""
    plain = inspect.isfunction(obj) or inspect.ismethod(obj) or inspect.isclass(obj)
    if callable(obj) and not plain and not inspect.isbuiltin(obj) and not inspect.ismodule(obj):
        return signature, return_annotation
    return None


def repair_underlines(lines: list[str]) -> list[str]:
    """Lengthen reStructuredText section underlines that are shorter than their title (one
    character short is a common slip; docutils warns "Title underline too short")."""
    out = list(lines)
    for i in range(1, len(out)):
        title, line = out[i - 1], out[i]
        if (
            title.strip()
            and UNDERLINE.match(line.strip())
            and len(line.strip()) < len(title.strip())
            and len(line) - len(line.lstrip()) == len(title) - len(title.lstrip())
            and len(title.strip()) - len(line.strip()) <= 3
        ):
            out[i] = line.rstrip() + line.strip()[0] * (len(title.rstrip()) - len(line.rstrip()))
    return out


def docstring_rubrics(
    app: Sphinx, what: str, name: str, obj: Any, options: Any, lines: list[str]
) -> None:
    """autodoc: turn Markdown section headings of a docstring (``## Description``) into
    reStructuredText rubrics, so Gymnasium-style docstrings render with their headings."""
    fixes = DOCSTRING_FIXES.get(name)
    if fixes:
        text = "\n".join(lines)
        for before, after in fixes:
            if before in text:
                text = text.replace(before, after)
            else:
                LOGGER.info(
                    "dg16m_docs: the docstring fix %r of %s no longer applies", before, name
                )
        lines[:] = text.split("\n")
    lines[:] = repair_underlines(repair_simple_tables(lines))
    if not app.env.docname.startswith("api/"):
        # a module docstring shown on a concept page (``automodule`` with ``:no-index:``):
        # its sections become rubrics, so two docstrings' "The subject" do not clash
        for i in range(len(lines) - 1):
            title, line = lines[i], lines[i + 1]
            if title.strip() and UNDERLINE.match(line.strip()) and len(line) >= len(title):
                indent = title[: len(title) - len(title.lstrip())]
                lines[i], lines[i + 1] = f"{indent}.. rubric:: {title.strip()}", ""
    for i, line in enumerate(lines):
        match = HEADING.match(line.strip())
        if match and (i == 0 or not lines[i - 1].strip()):
            indent = line[: len(line) - len(line.lstrip())]
            lines[i] = f"{indent}.. rubric:: {match.group(2)}"


# -------------------------------------------------------------------------------------------
# Environment pages
# -------------------------------------------------------------------------------------------


def _space_text(space: Any) -> str:
    """A Gymnasium space as a short Markdown text (Dict spaces: one line per key)."""
    from gymnasium import spaces

    if isinstance(space, spaces.Dict):
        items = [f"`{key}`: `{_space_repr(sub)}`" for key, sub in space.spaces.items()]
        return "`Dict`: " + ", ".join(items)
    return f"`{_space_repr(space)}`"


def _space_repr(space: Any) -> str:
    from gymnasium import spaces

    if isinstance(space, spaces.Box):
        low, high = space.low, space.high
        lo = f"{float(low.min()):g}" if (low == low.flat[0]).all() else "low"
        hi = f"{float(high.max()):g}" if (high == high.flat[0]).all() else "high"
        return f"Box({lo}, {hi}, {space.shape}, {space.dtype})"
    return repr(space)


def _keyword_arguments(cls: type) -> list[tuple[str, str, str]]:
    """``(name, default, annotation)`` of every keyword argument of ``cls`` (following
    ``**kwargs`` up the class hierarchy)."""
    found: dict[str, tuple[str, str, str]] = {}
    for klass in cls.__mro__:
        init = klass.__dict__.get("__init__")
        if init is None:
            continue
        try:
            signature = inspect.signature(init)
        except (TypeError, ValueError):
            continue
        more = False
        for parameter in list(signature.parameters.values())[1:]:
            if parameter.kind is parameter.VAR_KEYWORD:
                more = True
                continue
            if parameter.kind is parameter.VAR_POSITIONAL or parameter.name in found:
                continue
            default = (
                "required" if parameter.default is parameter.empty else f"`{parameter.default!r}`"
            )
            annotation = parameter.annotation
            text = "" if annotation is parameter.empty else str(annotation)
            text = text.replace("|", "\\|")
            found[parameter.name] = (parameter.name, default, f"`{text}`" if text else "")
        if not more:
            break
    return list(found.values())


def env_page(name: str, entry_point: str, max_steps: int | None) -> str:
    """The Markdown page of one registered environment."""
    import gymnasium

    env_id = f"dg16m_env/{name}"
    module_name, class_name = entry_point.split(":")
    module = importlib.import_module(module_name)
    cls = getattr(module, class_name)
    spec = gymnasium.spec(env_id)
    env = gymnasium.make(env_id)
    try:
        action_space, observation_space = env.action_space, env.observation_space
        metadata = dict(env.unwrapped.metadata)
    finally:
        env.close()

    class_doc = inspect.getdoc(cls) or ""
    uses_class = bool(split_docstring(class_doc)[1])
    summary_doc, sections = split_docstring(class_doc if uses_class else module.__doc__ or "")
    if not uses_class and summary_doc.startswith(f"``{env_id}``:"):
        # a module docstring opens with "``id``: summary"
        rest = summary_doc.split(":", 1)[1].strip()
        summary_doc = rest[:1].upper() + rest[1:]
    source = f"{cls.__module__}.{cls.__qualname__}" if uses_class else module_name

    vector = (spec.kwargs or {}).get("vector_kwargs", {})
    rows = [
        ("Id", f"`{env_id}` (alias `{name}`)"),
        ("Entry point", f"{{class}}`{module_name}.{class_name}`"),
        ("Action space", _space_text(action_space)),
        ("Observation space", _space_text(observation_space)),
        (
            "Episode",
            f"at most {max_steps} steps (`TimeLimit`)"
            if max_steps
            else "one step: terminates after it",
        ),
        ("Render modes", ", ".join(f"`{m}`" for m in metadata.get("render_modes", []))),
        ("Render fps", str(metadata.get("render_fps", ""))),
    ]
    if vector:
        rows.append(("Vector kwargs", f"`{vector!r}`"))
    rows.append(("Make", f'`gymnasium.make("{env_id}")` after `import dg16m_env`'))

    table = [f"* - {key}\n  - {value}" for key, value in rows]
    out = [
        f"# {name.removesuffix('-v0')}",
        "",
        f"```{{py:currentmodule}} {module_name}",
        "```",
        "",
        f"<!-- generated by docs/_ext/dg16m_docs.py from {source}; do not edit -->",
        "",
        fence(summary_doc, "eval-rst"),
        fence(
            "\n".join(table),
            "list-table",
            options={"header-rows": "0", "class": "env-summary", "widths": "20 80"},
        ),
    ]
    picture = PICTURES.get(name)
    if picture:
        file, caption = picture
        out.append(
            fence(
                caption,
                "figure",
                f"../_static/pictures/{file}",
                {"alt": f"a rendered trial of {env_id}", "width": PICTURE_WIDTHS.get(file, "100%")},
            )
        )
    arguments = _keyword_arguments(cls)
    if arguments:
        out += [
            "## Constructor arguments",
            "",
            f'Keyword arguments of `gymnasium.make("{env_id}", ...)` (from the signature of '
            f"{{class}}`~{module_name}.{class_name}` and the classes it passes `**kwargs` to; "
            "what each means is under *Arguments* below).",
            "",
            "| argument | default | type |",
            "|---|---|---|",
            *[f"| `{a}` | {d} | {t} |" for a, d, t in arguments],
            "",
        ]
    for section in sections:
        body = "\n".join(repair_simple_tables(section.body.splitlines()))
        out += [f"## {section.title}", "", fence(body, "eval-rst")]
    out += [
        "## API",
        "",
        f"{{class}}`{module_name}.{class_name}` in the API reference ({{py:mod}}`{module_name}`).",
        "",
    ]
    return "\n".join(out)


def env_index(names: list[str]) -> str:
    """The environments' index page: the package docstring, a table, the toctree."""
    import dg16m_env.envs as envs

    summary, _ = split_docstring(envs.__doc__ or "")
    lines = [
        "# Environments",
        "",
        "```{py:currentmodule} dg16m_env.envs",
        "```",
        "",
        "<!-- generated by docs/_ext/dg16m_docs.py; do not edit -->",
        "",
        fence(summary, "eval-rst"),
        "Every environment passes Gymnasium's and stable-baselines3's `check_env` with "
        "warnings as errors (tested). `info` always carries `success` and `is_success`; "
        '`render_mode="rgb_array"` renders offscreen (EGL or OSMesa).',
        "",
        "```python",
        "import gymnasium as gym",
        "import dg16m_env  # registers the environments",
        "",
        'env = gym.make("dg16m_env/DualGraspSelect-v0", render_mode="rgb_array")',
        "obs, info = env.reset(seed=0)",
        "obs, reward, terminated, truncated, info = env.step(env.action_space.sample())",
        "```",
        "",
        fence("\n".join(names), "toctree", options={"maxdepth": "1"}),
    ]
    return "\n".join(lines)


def generate_environments(folder: Path) -> None:
    """Write ``folder/index.md`` and one page per registered environment."""
    import dg16m_env  # noqa: F401  registers the environments
    from dg16m_env.envs import ENVIRONMENTS

    written = {"index.md"}
    for name, (entry_point, max_steps) in ENVIRONMENTS.items():
        write_if_changed(folder / f"{name}.md", env_page(name, entry_point, max_steps))
        written.add(f"{name}.md")
    write_if_changed(folder / "index.md", env_index(list(ENVIRONMENTS)))
    remove_stale(folder, written)


# -------------------------------------------------------------------------------------------
# API reference
# -------------------------------------------------------------------------------------------


def package_modules(package: str) -> list[str]:
    """The package and its public modules (no ``_private`` ones), sorted, found on disk
    without importing them."""
    root = Path(importlib.import_module(package).__file__).parent
    names = [package]
    for info in pkgutil.walk_packages([str(root)], package + "."):
        if not any(part.startswith("_") for part in info.name.split(".")):
            names.append(info.name)
    return sorted(names)


def first_sentence(module: str) -> str:
    """The first line of a module's docstring, read from its source (no import)."""
    spec = importlib.util.find_spec(module)
    if spec is None or spec.origin is None:
        return ""
    doc = ast.get_docstring(ast.parse(Path(spec.origin).read_text(encoding="utf-8"))) or ""
    line = doc.strip().split("\n\n")[0].replace("\n", " ")
    return line


def api_groups() -> dict[str, list[str]]:
    """Package (or subpackage) -> its public modules, the package first: one API page each."""
    groups: dict[str, list[str]] = {}
    for package in PACKAGES:
        modules = package_modules(package)
        packages = [m for m in modules if _is_package(m)]
        for module in modules:
            owner = max((p for p in packages if module == p or module.startswith(p + ".")), key=len)
            groups.setdefault(owner, []).append(module)
    return groups


def _is_package(module: str) -> bool:
    spec = importlib.util.find_spec(module)
    return spec is not None and spec.submodule_search_locations is not None


def generate_api(folder: Path) -> None:
    """Write ``folder/index.md`` (every module, with its summary) and one reStructuredText page
    per package or subpackage (autodoc writes reStructuredText), a section per module.

    One page per package rather than per module keeps the site's navigation short (the theme
    renders it into every page) and the build fast."""
    written = {"index.md"}
    index = [
        "# API reference",
        "",
        "<!-- generated by docs/_ext/dg16m_docs.py; do not edit -->",
        "",
        "From the docstrings (Google style): one page per package, a section per module. "
        "Dependencies point one way: `dg16m_core` <- `dataset_gen` <- `dg16m_env` <- "
        "(`baselines`, `leaderboard`).",
        "",
    ]
    groups = api_groups()
    for package in PACKAGES:
        summary = PACKAGE_SUMMARIES[package]
        index += [f"## `{package}`", "", summary[0].upper() + summary[1:] + ".", ""]
        index += ["| module | |", "|---|---|"]
        for group, modules in groups.items():
            if group != package and not group.startswith(package + "."):
                continue
            for module in modules:
                text = fence_inline(first_sentence(module)).replace("|", "\\|")
                index.append(f"| {{py:mod}}`{module}` | {text} |")
        index.append("")
    for group, modules in groups.items():
        title = f"``{group}``"
        page = [".. generated by docs/_ext/dg16m_docs.py; do not edit", "", title, "=" * len(title)]
        page += [""]
        for module in modules:
            if module != group:  # the package's own docstring opens the page
                heading = f"``{module}``"
                page += [heading, "-" * len(heading), ""]
            page.append(f".. automodule:: {module}")
            page += [
                f"   :{key}:{' ' + value if value else ''}"
                for key, value in AUTOMODULE_OPTIONS.items()
            ]
            page.append("")
        write_if_changed(folder / f"{group}.rst", "\n".join(page))
        written.add(f"{group}.rst")
    index += ["", fence("\n".join(groups), "toctree", options={"hidden": "", "maxdepth": "1"})]
    write_if_changed(folder / "index.md", "\n".join(index))
    remove_stale(folder, written)


AUTOMODULE_OPTIONS = {"members": "", "show-inheritance": ""}


def fence_inline(text: str) -> str:
    """A docstring's first sentence as Markdown table text: reStructuredText literals
    (````x````) become code spans and roles lose their markup."""
    text = re.sub(r":[a-z:]+:`~?\.?([^`<]*?)(?: <[^>]*>)?`", r"`\1`", text)
    return text.replace("``", "`")


# -------------------------------------------------------------------------------------------
# Command-line reference
# -------------------------------------------------------------------------------------------


def _subcommands(parser: argparse.ArgumentParser) -> Iterator[tuple[str, Any]]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            yield from action.choices.items()


def _walk(parser: Any, path: list[str]) -> Iterator[tuple[list[str], Any]]:
    yield path, parser
    for name, sub in _subcommands(parser):
        yield from _walk(sub, [*path, name])


def generate_cli(path: Path) -> None:
    """Write the ``--help`` of every ``dg16m`` command, from the parser itself."""
    from dg16m_core.cli import build_parser

    previous = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "100"  # argparse wraps to the terminal: fix it
    try:
        parser = build_parser()
        pages = [(p, sub.format_help()) for p, sub in _walk(parser, ["dg16m"])]
    finally:
        if previous is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = previous
    lines = [
        "# Command line",
        "",
        "<!-- generated by docs/_ext/dg16m_docs.py from dg16m_core.cli.build_parser; "
        "do not edit -->",
        "",
        "Every `dg16m` command and its `--help`, as `dg16m COMMAND --help` prints it (the "
        "text comes from the parser when the docs are built). Exit status: 0 on success; 1 "
        "when a run finished but some objects or meshes failed; 2 for bad input; 141 when the "
        "output pipe closed.",
        "",
    ]
    for words, text in pages:
        depth = min(len(words), 3)
        title = " ".join(words)
        lines += [f"{'#' * (depth + 1)} `{title}`", "", "```text", text.rstrip(), "```", ""]
    write_if_changed(path, "\n".join(lines))


# -------------------------------------------------------------------------------------------


# -------------------------------------------------------------------------------------------
# Cross-references
# -------------------------------------------------------------------------------------------


def _import(name: str) -> Any:
    """The object a dotted name stands for (longest importable module, then attributes), or
    None."""
    parts = name.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj: Any = importlib.import_module(".".join(parts[:cut]))
        except Exception:
            continue
        try:
            for attribute in parts[cut:]:
                obj = getattr(obj, attribute)
        except AttributeError:
            return None
        return obj
    return None


def _documented_name(env: Any, name: str) -> str | None:
    """Where a re-exported object is documented (``dg16m_env.physics.trial.judge`` is documented as
    ``dg16m_env.physics.trial_measures.judge``), or None."""
    objects = env.get_domain("py").objects
    obj = _import(name)
    if obj is None or inspect.ismodule(obj):
        return None
    module, qualname = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
    if isinstance(module, str) and isinstance(qualname, str):
        real = f"{module}.{qualname}"
        return real if real in objects and real != name else None
    last = name.rsplit(".", 1)[-1]  # data: find the documented name bound to the same object
    for candidate in objects:
        if candidate != name and candidate.rsplit(".", 1)[-1] == last and _import(candidate) is obj:
            return candidate
    return None


def resolve_reexports(app: Sphinx, env: Any, node: Any, contnode: Any) -> Any:
    """``missing-reference``: resolve a Python reference to a name re-exported by another
    module (or named relative to the current module) to where it is documented."""
    if node.get("refdomain") != "py":
        return None
    target = node["reftarget"].lstrip("~.")
    names = [target]
    for context in (node.get("py:class"), node.get("py:module")):
        if context:
            names.append(f"{context}.{target}")
    if node.get("py:module") and node.get("py:class"):
        names.append(f"{node['py:module']}.{node['py:class']}.{target}")
    domain = env.get_domain("py")
    for name in names:
        real = _documented_name(env, name)
        if real is None:
            continue
        for kind in (node["reftype"], "obj"):
            found = domain.resolve_xref(
                env, node["refdoc"], app.builder, kind, real, node, contnode
            )
            if found is not None:
                return found
    return None


def lenient_api_references(app: Sphinx, domain: Any, node: Any) -> bool | None:
    """``warn-missing-reference``: in text that autodoc takes from the code (docstrings, type
    hints; the API pages and ``automodule`` on other pages), an unresolved Python reference
    stays plain text, as without ``nitpicky``, and is listed in
    ``unresolved-api-references.txt`` beside the doctrees. Text written in ``docs/``
    (the environment pages' sections included) is checked strictly."""
    if domain is None or domain.name != "py":
        return None
    from_code = ":docstring of " in (node.source or "") or node.get("refdoc", "").startswith("api/")
    if not from_code:
        return None
    UNRESOLVED.add(f"{node['refdoc']}: {node['reftype']} {node['reftarget']}")
    return True


UNRESOLVED: set[str] = set()


def report_unresolved(app: Sphinx, exception: BaseException | None) -> None:
    """``build-finished``: write the API pages' unresolved references."""
    if exception is not None:
        return
    path = Path(app.doctreedir) / "unresolved-api-references.txt"
    path.write_text("".join(f"{line}\n" for line in sorted(UNRESOLVED)), encoding="utf-8")
    if UNRESOLVED:
        LOGGER.info(
            "%d unresolved references in docstrings (plain text): %s", len(UNRESOLVED), path
        )


def generate(app: Sphinx) -> None:
    """``builder-inited``: write the generated pages into the source folder."""
    source = Path(app.srcdir)
    generate_environments(source / "environments")
    generate_api(source / "api")
    generate_cli(source / "cli.md")


# -------------------------------------------------------------------------------------------
# Parameter tables
# -------------------------------------------------------------------------------------------


def attribute_docs(cls: type) -> dict[str, str]:
    """``name -> text`` of the ``Attributes:`` section of a Google-style class docstring."""
    doc = inspect.getdoc(cls) or ""
    found: dict[str, str] = {}
    inside, name = False, None
    for line in doc.splitlines():
        if line.strip() == "Attributes:":
            inside = True
            continue
        if not inside:
            continue
        if line and not line.startswith(" "):
            break
        match = re.match(r"^    (\w+): (.*)$", line)
        if match:
            name = match.group(1)
            found[name] = match.group(2).strip()
        elif name and line.strip():
            found[name] += " " + line.strip()
    return found


class ParametersDirective(SphinxDirective):
    """``{dg16m-parameters} dg16m_core.parameters.PAPER``: a table of a frozen dataclass
    instance's fields, their values and their meaning (from its class docstring), so the
    numbers on a page are the code's."""

    required_arguments = 1
    has_content = False

    def run(self) -> list[Any]:
        import dataclasses

        obj = _import(self.arguments[0])
        if obj is None or not dataclasses.is_dataclass(obj):
            raise self.error(f"expected a dataclass instance, found {self.arguments[0]!r}")
        meaning = attribute_docs(type(obj))
        table = nodes.table(classes=["dg16m-parameters"])
        group = nodes.tgroup(cols=3)
        table += group
        for width in (25, 15, 60):
            group += nodes.colspec(colwidth=width)
        head, body = nodes.thead(), nodes.tbody()
        group += head
        group += body
        head += self._row([nodes.Text("field")], [nodes.Text("value")], [nodes.Text("meaning")])
        for field in dataclasses.fields(obj):
            inline, messages = self.parse_inline(meaning.get(field.name, ""), lineno=self.lineno)
            body += self._row(
                [nodes.literal(text=field.name)],
                [nodes.literal(text=repr(getattr(obj, field.name)))],
                [*inline, *messages],
            )
        return [table]

    @staticmethod
    def _row(*cells: list[Any]) -> Any:
        row = nodes.row()
        for content in cells:
            entry = nodes.entry()
            paragraph = nodes.paragraph()
            paragraph.extend(content)
            entry += paragraph
            row += entry
        return row


#: Pages other work may add: listed in the root toctree (at ``<!-- optional pages -->``) only
#: when their file exists.
OPTIONAL_PAGES = ("ray_cluster",)


def optional_pages(app: Sphinx, docname: str, source: list[str]) -> None:
    """``source-read``: put the optional pages that exist into the root page's toctree."""
    if docname != app.config.root_doc:
        return
    present = [page for page in OPTIONAL_PAGES if (Path(app.srcdir) / f"{page}.md").exists()]
    source[0] = source[0].replace("<!-- optional pages -->", "\n".join(present))


_NAPOLEON_TYPE = re.compile(r"^:type: (.+)$")


def prose_before_colon(
    app: Sphinx, what: str, name: str, obj: Any, options: Any, lines: list[str]
) -> None:
    """``autodoc-process-docstring``, after napoleon: napoleon reads the first line of a data or
    attribute docstring as ``type: description``, so "The real benchmark's parameters: the
    defaults ..." came out as the type "The real benchmark's parameters". A "type" of two or more
    words (brackets aside, as in ``(N, 3) float``) is prose: it is put back in front of the
    text it was cut from."""
    if what not in ("data", "attribute", "property"):
        return
    for index, line in enumerate(lines):
        match = _NAPOLEON_TYPE.match(line)
        if match is None:
            continue
        words = re.sub(r"\[[^\]]*\]|\([^)]*\)", " ", match.group(1)).split()
        if len(words) < 2:
            return
        del lines[index]
        if index > 0 and not lines[index - 1].strip():
            del lines[index - 1]
        first = next((k for k, text in enumerate(lines) if text.strip()), None)
        if first is None:
            lines.insert(0, match.group(1))
        else:
            lines[first] = f"{match.group(1)}: {lines[first]}"
        return


def setup(app: Sphinx) -> dict[str, Any]:
    """Register the generators and the docstring hook."""
    app.connect("builder-inited", generate)
    app.connect("source-read", optional_pages)
    app.add_directive("dg16m-parameters", ParametersDirective)
    app.connect("autodoc-process-docstring", docstring_rubrics)
    app.connect("autodoc-process-docstring", prose_before_colon, priority=900)  # after napoleon
    app.connect("autodoc-process-signature", plain_signature_of_instances, priority=100)
    app.connect("missing-reference", resolve_reexports)
    app.connect("warn-missing-reference", lenient_api_references)
    app.connect("build-finished", report_unresolved)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
