"""The documentation site (docs/): it builds with warnings as errors, every internal link and
picture resolves, and its pages render in headless Chromium.

The site is built once per test session into a temporary folder (about 50 s of CPU: autodoc
imports every module), with ``sphinx-build -W --keep-going``: a broken cross-reference, a
malformed docstring or a missing page fails the build. Skipped, with the reason, when the docs
extra is not installed (``pip install -e '.[docs]'``) or Chromium is missing (the browser test
only).
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from html.parser import HTMLParser
from pathlib import Path
from typing import Any
from urllib.parse import unquote, urlsplit

import pytest
from browser import console_errors, screenshot, start_browser
from script_loader import load_script

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PICTURES = DOCS / "_static" / "pictures"
MAX_PICTURE_BYTES = 300 * 1024
MAX_PICTURES_BYTES = 2 * 1024 * 1024

for module, extra in (("sphinx", "sphinx"), ("myst_parser", "myst-parser"), ("furo", "furo")):
    pytest.importorskip(module, reason=f"{extra} is not installed: pip install -e '.[docs]'")


@pytest.fixture(scope="session")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The built site (``index.html`` and the rest), built with warnings as errors."""
    out = tmp_path_factory.mktemp("docs")
    html, doctrees = out / "html", out / "doctrees"
    command = [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html"]
    command += ["-d", str(doctrees), str(DOCS), str(html)]
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), "PYTHONHASHSEED": "0"}
    done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, env=env, timeout=600)
    problems = [
        line
        for line in done.stderr.splitlines()
        if "RemovedInSphinx" not in line and "set_application" not in line
    ]
    assert done.returncode == 0, "sphinx-build -W failed:\n" + "\n".join(problems[-60:])
    return html


class _Links(HTMLParser):
    """Every ``href``/``src`` of a page and every ``id`` (and ``name``) it defines."""

    def __init__(self) -> None:
        super().__init__()
        self.links: list[tuple[str, str]] = []
        self.ids: set[str] = set()

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        for key, value in attrs:
            if value is None:
                continue
            if key in ("id", "name"):
                self.ids.add(value)
            elif key in ("href", "src"):
                self.links.append((tag, value))


def _parse(path: Path) -> _Links:
    parser = _Links()
    parser.feed(path.read_text(encoding="utf-8"))
    return parser


def test_every_relative_link_resolves(site: Path) -> None:
    """Every relative ``href``/``src`` of every built page names a file of the site, and its
    ``#fragment`` an id on that page."""
    pages = {path: _parse(path) for path in site.rglob("*.html")}
    assert len(pages) > 20
    broken: list[str] = []
    for page, parsed in pages.items():
        for tag, link in parsed.links:
            parts = urlsplit(link)
            if parts.scheme or parts.netloc or link.startswith(("mailto:", "javascript:")):
                continue
            target = (page.parent / unquote(parts.path)).resolve() if parts.path else page
            if target.is_dir():
                target = target / "index.html"
            where = f"{page.relative_to(site)}: <{tag}> {link}"
            if not target.is_file():
                broken.append(f"{where} (no file)")
                continue
            if parts.fragment and target.suffix == ".html":
                ids = pages[target].ids if target in pages else _parse(target).ids
                if unquote(parts.fragment) not in ids:
                    broken.append(f"{where} (no anchor)")
    assert broken == [], "\n".join(broken[:50])


def test_pages_for_every_environment_and_package(site: Path) -> None:
    """A page per registered environment (with its picture, spaces and version history) and
    an API page per package, generated from the code."""
    from dg16m_env.envs import ENVIRONMENTS

    for name in ENVIRONMENTS:
        page = (site / "environments" / f"{name}.html").read_text(encoding="utf-8")
        for text in ("Action space", "Observation space", "Version History", "<img"):
            assert text.lower() in page.lower(), (name, text)
    for package in ("dataset_gen", "dg16m_env", "baselines", "leaderboard"):
        page = (site / "api" / f"{package}.html").read_text(encoding="utf-8")
        assert f'id="module-{package}"' in page
    # a constant's docstring "The real benchmark's parameters: the defaults ..." is prose, not
    # napoleon's "type: description" (docs/_ext/dg16m_docs.py, prose_before_colon)
    api = (site / "api" / "dg16m_env.benchmark.html").read_text(encoding="utf-8")
    entry = api[api.index('id="dg16m_env.benchmark.real.REAL_PARAMETERS"') :][:8000]
    entry = entry[: entry.index('id="dg16m_env.benchmark.real.REAL_LIMITS"')]
    assert "benchmark’s parameters: the defaults" in entry.replace("&#8217;", "’")
    assert "Type:" not in entry
    cli = (site / "cli.html").read_text(encoding="utf-8")
    assert "dg16m leaderboard serve" in cli
    assert "dg16m demo" in cli


# Pages whose docstrings are not checked yet: the environments are being rewritten, and
# baselines' and leaderboard's references still name private or undocumented code.
UNCHECKED_PAGES = ("api/dg16m_env.envs", "environments/", "api/baselines", "api/leaderboard")


def unresolved_references(doctrees: Path) -> list[str]:
    """The unresolved docstring references the build listed (``page: role target``), those on
    :data:`UNCHECKED_PAGES` aside."""
    listed = (doctrees / "unresolved-api-references.txt").read_text(encoding="utf-8")
    return [line for line in listed.splitlines() if not line.startswith(UNCHECKED_PAGES)]


def test_docstring_references_resolve(site: Path) -> None:
    """Issue 43: dataset_gen's and dg16m_env's docstrings name only documented things (an
    unresolved reference stays plain text, so the build itself does not fail on it)."""
    found = unresolved_references(site.parent / "doctrees")
    assert found == [], f"expected every reference to resolve, found {len(found)}: {found}"


def test_pictures_are_small() -> None:
    """The committed pictures of trials (scripts/docs_pictures.py) stay small."""
    files = [path for path in PICTURES.iterdir() if path.is_file()]
    expected = {"pose_trial.gif", "select_trial.png", "lift_episode.gif", "lift_v2_episode.gif"}
    assert {p.name for p in files} >= expected
    for path in files:
        assert path.stat().st_size <= MAX_PICTURE_BYTES, path
    assert sum(p.stat().st_size for p in files) <= MAX_PICTURES_BYTES


def test_tutorial_predictor_gives_valid_grasps() -> None:
    """The tutorial's toy predictor returns what a submission accepts, for a real observation."""
    from dataset_gen.sources.procedural import make_procedural_object
    from dg16m_env.benchmark.file import read_benchmark
    from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK
    from dg16m_env.subjects.observation import object_observation
    from dg16m_env.subjects.submission import hand_pose_faults

    module = load_script(DOCS / "tutorials" / "my_grasps.py")
    bench = read_benchmark(EMBEDDED_BENCHMARK)
    first = bench.objects[0]
    obj = make_procedural_object(first.family, seed=first.seed)
    poses, scores = module.predict(object_observation(obj))
    assert poses.shape[1:] == (2, 4, 4)
    assert scores.shape == (poses.shape[0],)
    assert [reason for bad, reason in hand_pose_faults(poses) if bad.any()] == []


# In headless Chromium (skipped when it is not installed)

PAGES = (
    ("index.html", "dg16m"),
    ("quickstart.html", "Quickstart"),
    ("environments/DualGraspPose-v0.html", "DualGraspPose"),
    ("environments/DualGraspLift-v0.html", "DualGraspLift"),
    ("tutorials/score_predictor.html", "Score your predictor"),
    ("formats.html", "File formats"),
    ("api/dg16m_env.html", "dg16m_env"),
)


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    """A headless Chromium driver shared by the browser test."""
    driver = start_browser()
    yield driver
    driver.quit()


@pytest.mark.parametrize(("page", "title"), PAGES, ids=[p for p, _ in PAGES])
def test_page_renders_in_chromium(
    browser: Any, site: Path, tmp_path: Path, page: str, title: str
) -> None:
    """The page loads without console errors, shows its title, the navigation and every
    picture; a screenshot is kept (``$DG16M_SCREENSHOTS`` when set)."""
    from selenium.webdriver.common.by import By

    console_errors(browser)  # empty the log
    browser.get((site / page).as_uri())
    assert title in browser.title
    assert console_errors(browser) == []
    assert browser.find_elements(By.CSS_SELECTOR, "div.sidebar-tree a.reference")
    heading = browser.find_element(By.CSS_SELECTOR, "article h1")
    assert heading.is_displayed()
    assert heading.text
    broken = browser.execute_script(
        "return Array.from(document.images)"
        ".filter(i => !(i.complete && i.naturalWidth > 0)).map(i => i.src)"
    )
    assert broken == []
    overflow = browser.execute_script(
        "return document.documentElement.scrollWidth - document.documentElement.clientWidth"
    )
    assert overflow <= 1, f"the page scrolls sideways by {overflow} px"
    name = page.replace("/", "_").replace(".html", ".png")
    assert screenshot(browser, tmp_path, f"docs_{name}").stat().st_size > 10_000


def test_the_docs_extra_pins_the_installed_sphinx_autodoc_typehints() -> None:
    """Issue 43: a reproducible docs build; sphinx-autodoc-typehints changes the rendered
    signatures and the warnings ``-W`` fails on between releases, so the docs extra pins the
    version the site is built with (the one installed here)."""
    from importlib.metadata import version

    tomllib = pytest.importorskip("tomllib")  # Python >= 3.11
    from packaging.requirements import Requirement  # a dependency of Sphinx

    with open(ROOT / "pyproject.toml", "rb") as handle:
        extras = tomllib.load(handle)["project"]["optional-dependencies"]
    pins = [
        str(req.specifier)
        for req in map(Requirement, extras["docs"])
        if req.name == "sphinx-autodoc-typehints" and (req.marker is None or req.marker.evaluate())
    ]
    installed = version("sphinx-autodoc-typehints")
    assert pins == [f"=={installed}"], f"expected the pin =={installed}, found {pins}"
