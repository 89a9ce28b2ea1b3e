"""Object library folders: parts files and manifests that were tampered with."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from dataset_gen import io
from dataset_gen.sources.library import load_library_object, read_parts, write_procedural_library
from dg16m_core.errors import Dg16mError, MeshError


@pytest.fixture(scope="module")
def library(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("lib")
    write_procedural_library(out, [("board", 0), ("ladder", 0)])
    return out


def test_round_trip_keeps_parts_and_frame(library: Path) -> None:
    obj = load_library_object(library, "ladder-0000000")
    assert obj.metadata == {"family": "ladder", "seed": 0, "split": "train"}
    assert obj.parts
    assert obj.is_watertight
    assert abs(obj.mesh.centroid).max() < 1e-7  # written centred, loaded without re-centring


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("{not json", "parse error at line 1"),
        (json.dumps({"format": "other"}), "expected a 'dg16m-parts' file"),
        (
            json.dumps({"format": "dg16m-parts", "schema_version": 9}),
            "expected schema_version 1, found 9",
        ),
        (json.dumps({"format": "dg16m-parts", "schema_version": 1, "parts": []}), "non-empty list"),
    ],
)
def test_malformed_parts_files(tmp_path: Path, content: str, message: str) -> None:
    path = tmp_path / "p.json"
    path.write_text(content)
    with pytest.raises(MeshError, match=message):
        read_parts(path)


def test_manifest_pointing_outside_the_folder_is_refused(library: Path, tmp_path: Path) -> None:
    manifest = json.loads((library / io.MANIFEST_NAME).read_text())
    manifest["entries"]["board-0000000"]["files"]["mesh"] = "../../etc/passwd"
    hostile = tmp_path / "hostile"
    hostile.mkdir()
    (hostile / io.MANIFEST_NAME).write_text(json.dumps(manifest))
    with pytest.raises(Dg16mError, match=r"\.\."):
        load_library_object(hostile, "board-0000000")
    with pytest.raises(MeshError, match="expected object 'chair-0000000'"):
        load_library_object(library, "chair-0000000")
