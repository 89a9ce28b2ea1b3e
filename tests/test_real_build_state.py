"""Carrying a real build between machines: pack, unpack, hashes checked, nothing overwritten."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest

from dataset_gen.io.manifest import new_manifest, write_manifest
from dg16m_env.benchmark.model import BenchmarkError
from dg16m_env.benchmark.real_build_state import restore_build_state, save_build_state


def _import_folder(root: Path, meshes: dict[str, bytes]) -> Path:
    root.mkdir(parents=True)
    entries = {}
    for object_id, data in meshes.items():
        (root / f"{object_id}.obj").write_bytes(data)
        entries[object_id] = {
            "status": "ok",
            "files": {"mesh": f"{object_id}.obj"},
            "sha256": hashlib.sha256(data).hexdigest(),
        }
    entries["broken"] = {"status": "failed", "files": {}, "error": "not repairable"}
    manifest = {**new_manifest("sweethome3d-import"), "entries": entries}
    (root / "manifest.json").write_text(json.dumps(manifest), encoding="utf-8")
    (root / "ATTRIBUTION.md").write_text("# attribution\n", encoding="utf-8")
    return root


def _build_folder(root: Path, done: dict[str, bytes]) -> Path:
    (root / "objects").mkdir(parents=True)
    manifest = new_manifest("benchmark", {"n_grasps": 200})
    for object_id, data in done.items():
        (root / "objects" / f"{object_id}.h5").write_bytes(data)
        manifest["entries"][object_id] = {
            "status": "ok",
            "files": {"benchmark": f"objects/{object_id}.h5"},
        }
    manifest["entries"]["c"] = {"status": "failed", "files": {}, "error": "c: too few pairs"}
    write_manifest(root, manifest)
    (root / "sources.json").write_text('{"a": "x"}\n', encoding="utf-8")
    return root


MESHES = {"a": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n" * 50, "b": b"v 0 0 1\n" * 80}


def test_save_then_restore_gives_the_same_bytes(tmp_path: Path) -> None:
    meshes = _import_folder(tmp_path / "meshes", MESHES)
    build = _build_folder(tmp_path / "build", {"a": b"HDF-a", "b": b"HDF-b"})
    state = tmp_path / "state"
    counts = save_build_state(meshes, build, state)
    assert (counts["meshes"], counts["objects"]) == (2, 2)
    assert counts["written"] > 0
    assert sorted(p.name for p in (state / "meshes").glob("*.xz")) == ["a.obj.xz", "b.obj.xz"]
    # a second save of the same folders writes nothing
    assert save_build_state(meshes, build, state)["written"] == 0

    out = restore_build_state(state, tmp_path / "m2", tmp_path / "b2")
    assert out == {"meshes": 2, "objects": 2, "written": 2 + 2 + 2 + 2}
    for name in ("a.obj", "b.obj", "manifest.json", "ATTRIBUTION.md"):
        assert (tmp_path / "m2" / name).read_bytes() == (meshes / name).read_bytes()
    for name in ("objects/a.h5", "objects/b.h5", "manifest.json", "sources.json"):
        assert (tmp_path / "b2" / name).read_bytes() == (build / name).read_bytes()
    # restoring again over an equal folder is a no-op
    assert restore_build_state(state, tmp_path / "m2", tmp_path / "b2")["written"] == 0


def test_save_drops_objects_the_build_forgot(tmp_path: Path) -> None:
    meshes = _import_folder(tmp_path / "meshes", MESHES)
    build = _build_folder(tmp_path / "build", {"a": b"HDF-a", "b": b"HDF-b"})
    state = tmp_path / "state"
    save_build_state(meshes, build, state)
    manifest = json.loads((build / "manifest.json").read_text())
    del manifest["entries"]["b"]
    write_manifest(build, manifest)
    assert save_build_state(meshes, build, state)["removed"] == 1
    assert not (state / "build" / "objects" / "b.h5.xz").exists()


def test_a_changed_mesh_is_refused_on_save_and_on_restore(tmp_path: Path) -> None:
    meshes = _import_folder(tmp_path / "meshes", MESHES)
    state = tmp_path / "state"
    save_build_state(meshes, None, state)
    (meshes / "a.obj").write_bytes(b"v 9 9 9\n")
    with pytest.raises(BenchmarkError, match=r"a\.obj: expected sha256"):
        save_build_state(meshes, None, state)
    # a packed file replaced by another mesh's bytes is refused on restore
    (state / "meshes" / "a.obj.xz").write_bytes((state / "meshes" / "b.obj.xz").read_bytes())
    with pytest.raises(BenchmarkError, match="expected an OBJ with sha256"):
        restore_build_state(state, tmp_path / "m2")
    assert not (tmp_path / "m2" / "manifest.json").exists()  # the import is not marked done


def test_restore_refuses_to_overwrite_a_different_file(tmp_path: Path) -> None:
    meshes = _import_folder(tmp_path / "meshes", MESHES)
    state = tmp_path / "state"
    save_build_state(meshes, None, state)
    (tmp_path / "m2").mkdir()
    (tmp_path / "m2" / "a.obj").write_bytes(b"mine\n")
    with pytest.raises(BenchmarkError, match="found different bytes"):
        restore_build_state(state, tmp_path / "m2")
    assert (tmp_path / "m2" / "a.obj").read_bytes() == b"mine\n"


def test_not_a_state_folder(tmp_path: Path) -> None:
    with pytest.raises(BenchmarkError, match="expected a build state folder"):
        restore_build_state(tmp_path, tmp_path / "m")
    _import_folder(tmp_path / "meshes", MESHES)
    with pytest.raises(BenchmarkError, match="expected a build folder"):
        save_build_state(tmp_path / "meshes", tmp_path / "nothing", tmp_path / "s")


def test_a_truncated_object_file_is_refused(tmp_path: Path) -> None:
    meshes = _import_folder(tmp_path / "meshes", MESHES)
    build = _build_folder(tmp_path / "build", {"a": b"HDF-a" * 100})
    state = tmp_path / "state"
    save_build_state(meshes, build, state)
    packed = state / "build" / "objects" / "a.h5.xz"
    packed.write_bytes(packed.read_bytes()[:20])
    with pytest.raises(BenchmarkError, match=r"a\.h5\.xz: expected xz data"):
        restore_build_state(state, tmp_path / "m2", tmp_path / "b2")
    assert not (tmp_path / "b2" / "manifest.json").exists()  # the build is not marked done
