"""Real objects from Debian's ``sweethome3d-furniture`` libraries: catalogue, filter, import.

The package (``apt-get install sweethome3d-furniture``, 1.8-1) installs five zip libraries
``/usr/share/sweethome3d/furniture/*.sh3f`` (Scopia, BlendSwap-CC-0, BlendSwap-CC-BY,
KatorLegaz, Reallusion). Each holds ``PluginFurnitureCatalog.properties`` (a Java properties
file: per model ``id#N``, ``name#N``, ``category#N``, ``creator#N``, ``model#N``,
``width#N`` / ``depth#N`` / ``height#N`` in cm, optional ``modelRotation#N``) and the OBJ models.
Licences are per library (``/usr/share/doc/sweethome3d-furniture/copyright``): CC0 for
BlendSwap-CC-0, CC-BY-3.0 for the others; BlendSwap models carry their own licence files too.

Which models are dual-arm objects (:func:`exclusion_reason`, in this order): not people
(category "Characters"), doors or windows, staircases or vehicles; not plants (a word of
:data:`PLANT_WORDS` in the name or tags); not textiles (the name's head noun, :func:`head_word`,
is one of :data:`TEXTILE_WORDS`: a "Towel" or "Hanging clothes", not a "Towel rack", a "Clothes
basket" or a "Chair with cushion"); not flat sheets or poles (catalogue longest / shortest side
at most :data:`MAX_ASPECT`, 12). Lamps are rigid objects and are kept (the first split left out
the Lights category and every model with a light source, any model with a textile word in its
name or tags, and every model flatter than 8: :data:`FILTER_VERSION` 1).

How a model becomes an object (:func:`import_model`), all in metres:

1. the OBJ's coordinates are turned by ``modelRotation`` and scaled per axis to the
   catalogue's width (x), height (y) and depth (z), as Sweet Home 3D shows it; then turned
   from y-up to z-up;
2. sized to a longest side in [0.3, 1.2] m (:func:`target_longest_side`): a model whose
   catalogue size is in that range keeps it; any other is scaled uniformly to a longest side
   drawn uniformly from the range with a seed per model id (DA2 scaled its ShapeNet objects
   into the same range);
3. repaired into one watertight volume of at most ``target_faces`` faces
   (:func:`dataset_gen.real.repair.repair_mesh`), and the deviation from the scaled source surface
   measured both ways (:func:`dataset_gen.real.repair.surface_deviation`). A repair that keeps only
   part of the model (an axis shorter than the source's by more than
   :data:`dataset_gen.real.repair.MAX_SIZE_LOSS` of its longest side, again on a grid of half the
   voxel size) fails: thin pipes or straps vanished, or only the largest of its pieces was left.

:func:`import_library` writes ``<id>.obj`` files, a ``manifest.json`` (per object: library,
model path, name, category, creator, licence and its files, catalogue size, rotation, scale
factors, repair report, deviation, faces, sha256 of the OBJ bytes) and ``ATTRIBUTION.md``
(creator, licence, source and "modified: ..." per object, as CC-BY-3.0 requires). A model that
cannot be read or repaired is recorded with its reason and skipped.
"""

from __future__ import annotations

import hashlib
import io
import math
import re
import zipfile
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from dataset_gen.real.orientation import Y_UP_TO_Z_UP
from dataset_gen.real.repair import RepairParameters, repair_mesh, surface_deviation
from dataset_gen.sources.object_source import object_seed
from dg16m_core.atomic import write_bytes_atomic, write_text_atomic
from dg16m_core.errors import Dg16mError

DEFAULT_ROOT = Path("/usr/share/sweethome3d/furniture")
"""Where Debian's package installs the libraries."""

COPYRIGHT_FILE = Path("/usr/share/doc/sweethome3d-furniture/copyright")

PACKAGE_HINT = (
    "the Sweet Home 3D furniture libraries are missing: install Debian's package with "
    "'apt-get install -y sweethome3d-furniture' (or pass --root to a folder of *.sh3f files)"
)

LIBRARY_LICENCES: Mapping[str, str] = {
    "BlendSwap-CC-0": "CC0-1.0",
    "BlendSwap-CC-BY": "CC-BY-3.0",
    "KatorLegaz": "CC-BY-3.0-US",
    "Reallusion": "CC-BY-3.0-US",
    "Scopia": "CC-BY-3.0",
}
"""Licence of each library (Debian's copyright file); SPDX identifiers."""

LIBRARY_COPYRIGHT: Mapping[str, str] = {
    "BlendSwap-CC-0": "2014, Emmanuel Puybaret eTeks and other contributors",
    "BlendSwap-CC-BY": "The BlendSwap contributors",
    "KatorLegaz": "2003-2008, Andrew Kator & Jennifer Legaz",
    "Reallusion": "2008-2011, Reallusion",
    "Scopia": "2010-2012, Scopia Visual Interfaces Systems, s.l.",
}

EXCLUDED_CATEGORIES = ("Characters", "Doors and windows", "Staircases", "Vehicles")
"""Catalogue categories that are not dual-arm objects (people, openings, stairs, cars)."""

FILTER_VERSION = 3
"""The version of :func:`exclusion_reason`: 1 also left out lamps (the Lights category and any
light source) and every model with a textile word anywhere in its name or tags (a washing
machine tagged "clothes"); 2 keeps both (module docstring); 3 allows a longest / shortest side
up to 12 instead of 8 (:data:`MAX_ASPECT`)."""

PLANT_WORDS = (
    "plant", "tree", "flower", "flowers", "bush", "palm", "cactus", "lily", "orchid", "bonsai",
    "fern", "grass", "hedge", "rose", "roses", "tulip", "ivy", "bamboo", "shrub",
)  # fmt: skip
"""A model with one of these words in its name or tags is a plant (left out)."""
TEXTILE_WORDS = (
    "rug", "carpet", "curtain", "curtains", "towel", "towels", "blanket", "cushion", "pillow",
    "drape", "drapes", "mat", "doormat", "tablecloth", "duvet", "sheet", "sheets", "clothes",
    "shirt", "dress", "coat", "jacket", "bathmat", "glove", "skirt", "trousers", "suit",
    "mattress", "futon",
)  # fmt: skip
"""A model whose name's head noun (:func:`head_word`) is one of these is a textile (left out)."""

MAX_ASPECT = 12.0
"""Largest catalogue longest / shortest side of an object (flatter or thinner is a sheet or a
pole that two parallel-jaw hands cannot share). Filter versions 1 and 2 used 8, which left out
books, plates, chopping boards, a pallet, tools, railings and a flat TV (35 models from 8 to 12,
thin objects that a parallel jaw holds well); past 12 are signs, sockets, carpets and road
markings."""

SIZE_RANGE_M = (0.3, 1.2)
"""Longest side of every imported object (m), the paper's (DA2's) range."""


class SweetHomeError(Dg16mError, ValueError):
    """The libraries are missing or malformed, or a model cannot be imported."""


# --------------------------------------------------------------------------------------------
# Catalogue
# --------------------------------------------------------------------------------------------


def parse_properties(text: str) -> dict[str, str]:
    """A Java ``.properties`` text as ``{key: value}`` (comments ``#``/``!``, ``key=value``,
    ``key:value`` or ``key value``, backslash line continuations, ``\\uXXXX`` escapes)."""
    out: dict[str, str] = {}
    pending = ""
    for raw in text.splitlines():
        line = raw.lstrip()
        if not pending and (not line or line[0] in "#!"):
            continue
        trailing = len(line) - len(line.rstrip("\\"))
        if trailing % 2 == 1:
            pending += line[:-1]
            continue
        line, pending = pending + line, ""
        match = re.match(r"((?:\\.|[^=:\s\\])*)\s*[=:\s]?\s*(.*)$", line)
        if match is None:  # pragma: no cover - the pattern matches any line
            continue
        out[_unescape(match.group(1))] = _unescape(match.group(2))
    return out


def _unescape(text: str) -> str:
    specials = {"t": "\t", "n": "\n", "r": "\r", "f": "\f"}

    def one(match: re.Match[str]) -> str:
        if match.group(1):
            return chr(int(match.group(1), 16))
        return specials.get(match.group(2), match.group(2))

    return re.sub(r"\\u([0-9a-fA-F]{4})|\\(.)", one, text)


@dataclass(frozen=True)
class CatalogEntry:
    """One model of a library's catalogue (sizes in cm, as the catalogue gives them).

    Attributes:
        object_id: our id, ``<library>-<model key>`` in lower case (file-name safe, unique).
        library: the library's file stem (e.g. ``"Scopia"``).
        catalog_id: the catalogue's ``id#N``.
        name, category, creator, tags: the catalogue's fields.
        model: path of the OBJ inside the library's zip.
        width, depth, height: catalogue size (cm) along the model's x, z and y.
        model_rotation: (3, 3) row-major rotation applied to the model first (identity if none).
        door_or_window, light: the catalogue's flags.
        licence: SPDX id of the library's licence.
        licence_files: the model's own licence files inside the zip (BlendSwap).
    """

    object_id: str
    library: str
    catalog_id: str
    name: str
    category: str
    creator: str
    tags: str
    model: str
    width: float
    depth: float
    height: float
    model_rotation: tuple[float, ...] = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    door_or_window: bool = False
    light: bool = False
    licence: str = ""
    licence_files: tuple[str, ...] = field(default=())

    @property
    def size_m(self) -> np.ndarray:
        """(3,) catalogue size along the object's x, y, z after turning y-up to z-up (m)."""
        return np.array([self.width, self.depth, self.height], dtype=np.float64) / 100.0

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["model_rotation"] = list(self.model_rotation)
        out["licence_files"] = list(self.licence_files)
        return out


def _slug(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-")


def _number(props: Mapping[str, str], key: str, library: str) -> float:
    try:
        value = float(props[key])
    except (KeyError, ValueError):
        raise SweetHomeError(
            f"{library}: expected a number for {key}, found {props.get(key)!r}"
        ) from None
    if not (math.isfinite(value) and value > 0):
        raise SweetHomeError(f"{library}: expected a positive size for {key}, found {value}")
    return value


def _rotation(text: str | None, library: str, key: str) -> tuple[float, ...]:
    if not text:
        return CatalogEntry.model_rotation
    values = tuple(float(v) for v in text.split())
    if len(values) != 9:
        raise SweetHomeError(f"{library}: expected 9 numbers for {key}, found {text!r}")
    return values


def library_files(root: str | Path = DEFAULT_ROOT) -> list[Path]:
    """The ``*.sh3f`` libraries under ``root``, sorted.

    Raises:
        SweetHomeError: none there (the message says what to install).
    """
    folder = Path(root)
    files = sorted(folder.glob("*.sh3f")) if folder.is_dir() else []
    if not files:
        raise SweetHomeError(
            f"{folder}: expected *.sh3f furniture libraries, found none; {PACKAGE_HINT}"
        )
    return files


def read_catalog(path: str | Path) -> list[CatalogEntry]:
    """Every model of one library, in catalogue order.

    Raises:
        SweetHomeError: not a zip, no catalogue, or a malformed entry.
    """
    path = Path(path)
    library = path.stem
    try:
        with zipfile.ZipFile(path) as archive:
            names = archive.namelist()
            text = archive.read("PluginFurnitureCatalog.properties").decode("latin-1")
    except (zipfile.BadZipFile, KeyError, OSError) as exc:
        raise SweetHomeError(
            f"{path}: expected a furniture library (zip with PluginFurnitureCatalog.properties), "
            f"found {type(exc).__name__}: {exc}"
        ) from None
    props = parse_properties(text)
    numbers = sorted({int(k.split("#", 1)[1]) for k in props if re.fullmatch(r"[A-Za-z]+#\d+", k)})
    licence = LIBRARY_LICENCES.get(library, props.get("license", "unknown"))
    licence_names = [n for n in names if "licen" in n.lower() and n.count("/") >= 2]
    entries = []
    seen: set[str] = set()
    for n in numbers:
        catalog_id = props.get(f"id#{n}", f"{library}#{n}")
        model = props.get(f"model#{n}", "").lstrip("/")
        key = catalog_id.split("#", 1)[-1]
        object_id = f"{_slug(library)}-{_slug(key)}"
        while object_id in seen:
            object_id += "-b"
        seen.add(object_id)
        folder = model.rsplit("/", 1)[0] + "/" if "/" in model else ""
        entries.append(
            CatalogEntry(
                object_id=object_id,
                library=library,
                catalog_id=catalog_id,
                name=props.get(f"name#{n}", ""),
                category=props.get(f"category#{n}", ""),
                creator=props.get(f"creator#{n}", ""),
                tags=props.get(f"tags#{n}", ""),
                model=model,
                width=_number(props, f"width#{n}", library),
                depth=_number(props, f"depth#{n}", library),
                height=_number(props, f"height#{n}", library),
                model_rotation=_rotation(
                    props.get(f"modelRotation#{n}"), library, f"modelRotation#{n}"
                ),
                door_or_window=props.get(f"doorOrWindow#{n}", "false").strip() == "true",
                light=f"lightSourceX#{n}" in props,
                licence=licence,
                licence_files=tuple(
                    sorted(x for x in licence_names if folder and x.startswith(folder))
                ),
            )
        )
    return entries


def read_catalogs(root: str | Path = DEFAULT_ROOT) -> list[CatalogEntry]:
    """Every model of every library under ``root`` (libraries sorted by name)."""
    return [entry for path in library_files(root) for entry in read_catalog(path)]


def _words(text: str) -> set[str]:
    return set(re.findall(r"[a-z]+", text.lower()))


def head_word(name: str) -> str:
    """The head noun of an English catalogue name: the last word before "with", "and", "for",
    "of", "on", "in", a comma or a bracket ("Paper towel holder" -> "holder", "Chair with
    cushion" -> "chair"); "" for a name without letters."""
    first = re.split(r"\b(?:with|and|for|of|on|in)\b|[,(]", name.lower())[0]
    words = re.findall(r"[a-z]+", first)
    return words[-1] if words else ""


def exclusion_reason(entry: CatalogEntry) -> str | None:
    """Why a model is not a dual-arm object (module docstring), or ``None`` if it is one."""
    if entry.category in EXCLUDED_CATEGORIES:
        return f"category {entry.category!r}"
    if entry.door_or_window:
        return "door or window"
    words = _words(f"{entry.name} {entry.tags}")
    if words & set(PLANT_WORDS):
        return f"plant ({', '.join(sorted(words & set(PLANT_WORDS)))})"
    head = head_word(entry.name)
    if head in TEXTILE_WORDS:
        return f"textile ({head})"
    size = entry.size_m
    aspect = float(size.max() / size.min())
    if aspect > MAX_ASPECT:
        return f"flat or thin (longest / shortest side {aspect:.1f} > {MAX_ASPECT:g})"
    return None


def usable_entries(entries: Iterable[CatalogEntry]) -> list[CatalogEntry]:
    """The entries :func:`exclusion_reason` keeps, in the given order."""
    return [e for e in entries if exclusion_reason(e) is None]


# --------------------------------------------------------------------------------------------
# One model
# --------------------------------------------------------------------------------------------


def target_longest_side(entry: CatalogEntry, seed: int) -> float:
    """The imported object's longest side (m): the catalogue's when it lies in
    :data:`SIZE_RANGE_M`, else drawn uniformly from the range (seeded by ``seed`` and the id)."""
    low, high = SIZE_RANGE_M
    longest = float(entry.size_m.max())
    if low <= longest <= high:
        return longest
    rng = np.random.default_rng(object_seed(seed, f"sweethome3d-size:{entry.object_id}"))
    return float(rng.uniform(low, high))


def read_model(entry: CatalogEntry, root: str | Path = DEFAULT_ROOT) -> trimesh.Trimesh:
    """The model's OBJ from its library, as one triangle soup in the file's units.

    Raises:
        SweetHomeError: the library or model is missing or holds no triangles.
    """
    path = Path(root) / f"{entry.library}.sh3f"
    try:
        with zipfile.ZipFile(path) as archive:
            data = archive.read(entry.model)
    except (OSError, KeyError, zipfile.BadZipFile) as exc:
        raise SweetHomeError(
            f"{entry.object_id}: expected model {entry.model} in {path}, found "
            f"{type(exc).__name__}: {exc}"
        ) from None
    try:
        loaded = trimesh.load(
            io.BytesIO(data), file_type="obj", force="mesh", process=False, skip_materials=True
        )
    except (ValueError, IndexError) as exc:
        raise SweetHomeError(f"{entry.object_id}: cannot read {entry.model}: {exc}") from None
    if len(getattr(loaded, "faces", ())) == 0:
        raise SweetHomeError(f"{entry.object_id}: expected triangles in {entry.model}, found none")
    return trimesh.Trimesh(loaded.vertices, loaded.faces, process=True)


def catalog_mesh(
    entry: CatalogEntry, mesh: trimesh.Trimesh, seed: int
) -> tuple[trimesh.Trimesh, dict[str, Any]]:
    """The model turned, sized to the catalogue, turned z-up and sized to
    :func:`target_longest_side`, centred on its bounding box (module docstring, steps 1-2).

    Returns:
        ``(mesh in metres, {"axis_scale": [sx, sy, sz], "scale": s, "longest_side_m": L})``.
    """
    vertices = (
        np.asarray(mesh.vertices, dtype=np.float64) @ np.reshape(entry.model_rotation, (3, 3)).T
    )
    extents = np.ptp(vertices, axis=0)
    if not np.all(extents > 0):
        raise SweetHomeError(
            f"{entry.object_id}: expected a model with volume, found extents {extents}"
        )
    catalogue = np.array([entry.width, entry.height, entry.depth]) / 100.0  # model x, y, z
    axis_scale = catalogue / extents
    vertices = (vertices * axis_scale) @ Y_UP_TO_Z_UP.T  # as objects repair --up y
    longest = target_longest_side(entry, seed)
    scale = longest / float(np.ptp(vertices, axis=0).max())
    vertices *= scale
    vertices -= 0.5 * (vertices.min(axis=0) + vertices.max(axis=0))
    info = {
        "axis_scale": [float(v) for v in axis_scale],
        "scale": float(scale),
        "longest_side_m": float(longest),
        "proportion_mismatch": float(np.max(np.abs(np.log(axis_scale / np.median(axis_scale))))),
    }
    return trimesh.Trimesh(vertices, mesh.faces, process=False), info


def sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def import_model(
    entry: CatalogEntry,
    out: str | Path,
    *,
    root: str | Path = DEFAULT_ROOT,
    seed: int = 0,
    repair: RepairParameters | None = None,
) -> dict[str, Any]:
    """Import one model into ``out/<id>.obj`` (module docstring); returns its manifest entry
    (``status`` "ok" with the fields, or "failed" with ``error``; never raises for a bad model)."""
    repair = repair or RepairParameters()
    base = {"source": entry.to_dict()}
    try:
        source = read_model(entry, root)
        scaled, sizing = catalog_mesh(entry, source, seed)
        repaired, report = repair_mesh(scaled, repair)
    except Dg16mError as exc:  # MeshError and SweetHomeError: this model only
        return {**base, "status": "failed", "files": {}, "error": str(exc)}
    rng = np.random.default_rng(object_seed(seed, f"sweethome3d-deviation:{entry.object_id}"))
    deviation = surface_deviation(repaired, scaled, rng=rng)
    text = repaired.export(file_type="obj", include_normals=False, include_texture=False)
    data = f"# {entry.object_id}: {entry.name} ({entry.library}, {entry.licence}); see ATTRIBUTION.md\n{text}".encode()
    name = f"{entry.object_id}.obj"
    write_bytes_atomic(Path(out) / name, data)
    return {
        **base,
        "status": "ok",
        "files": {"mesh": name},
        "sha256": sha256_bytes(data),
        "sizing": sizing,
        "extents_m": [float(v) for v in repaired.extents],
        "faces": len(repaired.faces),
        "volume_m3": float(repaired.volume),
        "repair": {**repair.to_dict(), **report.to_dict()},
        "deviation_m": deviation.to_dict(),
        "modified": modification_note(sizing, report.pitch, report.faces),
    }


def modification_note(sizing: Mapping[str, Any], pitch: float, faces: int) -> str:
    """What was changed (CC-BY-3.0's "modified: ..."), one line."""
    return (
        f"scaled to the catalogue size and then by {sizing['scale']:.4g} to a longest side of "
        f"{sizing['longest_side_m']:.3f} m, turned z-up, rebuilt as one watertight volume by a "
        f"filled-voxel remesh at {1000 * pitch:.1f} mm, Taubin-smoothed and decimated to "
        f"{faces} faces; materials and textures dropped"
    )


# --------------------------------------------------------------------------------------------
# Attribution
# --------------------------------------------------------------------------------------------


def attribution_text(
    entries: Sequence[Mapping[str, Any]],
    *,
    subject: str = "The meshes in this folder",
    note: str = "",
) -> str:
    """``ATTRIBUTION.md`` for imported objects (manifest entries with ``status`` "ok").

    Args:
        entries: the import manifest's entries of the objects to attribute.
        subject: what holds the derived meshes (the first words of the text).
        note: a closing paragraph (what the file beside it carries), or none.
    """
    lines = [
        "# Attribution",
        "",
        f"{subject} are derived from the 3D models of Debian's",
        "`sweethome3d-furniture` package (Sweet Home 3D additional furniture libraries,",
        "https://www.sweethome3d.com/importModels.jsp). Each model keeps its licence:",
        "CC-BY-3.0 (https://creativecommons.org/licenses/by/3.0/) or CC0-1.0",
        "(https://creativecommons.org/publicdomain/zero/1.0/). Every mesh was modified as",
        "stated below; the originals are in the libraries named.",
        "",
        "| object | model | creator | library (copyright) | licence | modified |",
        "|---|---|---|---|---|---|",
    ]
    for entry in sorted(entries, key=lambda e: e["source"]["object_id"]):
        src = entry["source"]
        library = f"{src['library']} ({LIBRARY_COPYRIGHT.get(src['library'], 'see library')})"
        files = (
            f"; licence files: {', '.join(src['licence_files'])}" if src["licence_files"] else ""
        )
        lines.append(
            f"| {src['object_id']} | {src['name']} (`{src['model']}`) | {src['creator'] or 'unknown'} "
            f"| {library} | {src['licence']}{files} | {entry['modified']} |"
        )
    if note:
        lines += ["", note]
    return "\n".join(lines) + "\n"


def write_attribution(out: str | Path, entries: Sequence[Mapping[str, Any]]) -> Path:
    path = Path(out) / "ATTRIBUTION.md"
    write_text_atomic(path, attribution_text([e for e in entries if e.get("status") == "ok"]))
    return path


# --------------------------------------------------------------------------------------------
# A whole import
# --------------------------------------------------------------------------------------------

IMPORT_KIND = "sweethome3d-import"
"""``kind`` of an import folder's manifest."""


def _import_task(
    entry: CatalogEntry, out: str, root: str, seed: int, repair: RepairParameters
) -> dict[str, Any]:
    return import_model(entry, out, root=root, seed=seed, repair=repair)


def select_entries(
    entries: Sequence[CatalogEntry],
    *,
    ids: Sequence[str] | None = None,
    categories: Sequence[str] | None = None,
    limit: int | None = None,
) -> list[CatalogEntry]:
    """The usable entries (:func:`exclusion_reason`) restricted to ``ids`` (in that order; an
    id that is excluded or unknown is an error naming why), ``categories`` and the first
    ``limit``."""
    by_id = {e.object_id: e for e in entries}
    if ids is not None:
        chosen = []
        for object_id in ids:
            if object_id not in by_id:
                raise SweetHomeError(
                    f"--ids: expected ids of the catalogue (e.g. {next(iter(by_id), '?')!r}), "
                    f"found {object_id!r}"
                )
            reason = exclusion_reason(by_id[object_id])
            if reason is not None:
                raise SweetHomeError(f"--ids: {object_id} is excluded: {reason}")
            chosen.append(by_id[object_id])
    else:
        chosen = usable_entries(entries)
    if categories:
        known = sorted({e.category for e in entries})
        unknown = [c for c in categories if c not in known]
        if unknown:
            raise SweetHomeError(f"--category: expected one of {known}, found {unknown}")
        chosen = [e for e in chosen if e.category in categories]
    if limit is not None:
        chosen = chosen[:limit]
    if not chosen:
        raise SweetHomeError("expected at least one model to import, found none selected")
    return chosen


def import_library(
    out: str | Path,
    entries: Sequence[CatalogEntry],
    *,
    root: str | Path = DEFAULT_ROOT,
    seed: int = 0,
    repair: RepairParameters | None = None,
    workers: int = 1,
    progress: bool = True,
    keep_failed: bool = False,
) -> dict[str, Any]:
    """Import ``entries`` into ``out`` (resumable: finished objects are skipped, and with
    ``keep_failed`` the ones that failed too: a repair fails the same way again); writes
    ``manifest.json`` (kind :data:`IMPORT_KIND`) and ``ATTRIBUTION.md``; returns the manifest.

    Raises:
        SweetHomeError: ``out`` is not a folder or holds an import made with other parameters.
    """
    from dataset_gen.pipeline.parallel import run_resumable

    repair = repair or RepairParameters()
    root_path = Path(out)
    if root_path.exists() and not root_path.is_dir():
        raise SweetHomeError(f"--out: expected a folder, found a file {root_path}")
    manifest = run_resumable(
        _import_task,
        entries,
        (str(root_path), str(root), int(seed), repair),
        root=root_path,
        kind=IMPORT_KIND,
        parameters={
            "seed": int(seed),
            "repair": repair.to_dict(),
            "size_range_m": list(SIZE_RANGE_M),
        },
        folders=(".",),
        error=SweetHomeError,
        workers=workers,
        progress=progress,
        desc="import",
        keep_failed=keep_failed,
    )
    write_attribution(root_path, list(manifest["entries"].values()))
    return manifest


def import_summary(manifest: Mapping[str, Any]) -> dict[str, Any]:
    """Counts, faces, times and deviations (mm percentiles over objects) of an import."""
    entries = list(manifest["entries"].values())
    ok = [e for e in entries if e["status"] == "ok"]
    out: dict[str, Any] = {"objects": len(entries), "ok": len(ok), "failed": len(entries) - len(ok)}
    if ok:

        def pct(values: Sequence[float]) -> list[float]:
            return [round(float(v), 3) for v in np.percentile(values, [10, 50, 90])]

        out["faces_p10_p50_p90"] = pct([e["faces"] for e in ok])
        out["seconds_p10_p50_p90"] = pct([e["repair"]["seconds"] for e in ok])
        out["to_source_mean_mm_p10_p50_p90"] = pct(
            [1000 * e["deviation_m"]["to_source_mean"] for e in ok]
        )
        out["to_source_p95_mm_p10_p50_p90"] = pct(
            [1000 * e["deviation_m"]["to_source_p95"] for e in ok]
        )
        out["from_source_p95_mm_p10_p50_p90"] = pct(
            [1000 * e["deviation_m"]["from_source_p95"] for e in ok]
        )
    out["failures"] = {e["source"]["object_id"]: e["error"] for e in entries if e["status"] != "ok"}
    return out
