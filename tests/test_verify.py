"""``dg16m verify``: recompute stored force-closure verdicts and explain disagreements.

Synthetic files are built at test time on a box (exact contacts on its faces, verdicts from
:func:`dataset_gen.force_closure.evaluate`); the real release file comes from the ``real_data``
fixture and skips when ``../shared`` is absent.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import trimesh

from dataset_gen import io
from dataset_gen.force_closure import evaluate
from dataset_gen.pipeline.verify import verify_file
from dg16m_core.cli import main
from dg16m_core.errors import Dg16mError, MeshError

HALF = np.array([0.2, 0.15, 0.1])  # box half extents (m)
N_PAIRS = 40


def _face_point(rng: np.random.Generator, axis: int, sign: float) -> tuple[np.ndarray, np.ndarray]:
    """A point inside the face of the box normal to ``axis`` on side ``sign`` (away from edges
    and from the triangles' shared diagonal is not needed: both halves have the same normal)."""
    p = rng.uniform(-0.8, 0.8, size=3) * HALF
    p[axis] = sign * HALF[axis]
    n = np.zeros(3)
    n[axis] = sign
    return p, n


def _box_file(
    tmp_path: Path,
    *,
    two_sided: bool = False,
    seed: int = 0,
    convention: str = "physical",
) -> tuple[Path, Path, np.ndarray]:
    """Write ``box.obj`` and ``box.h5`` (verdicts from evaluate). Returns paths and the normals
    used. With ``two_sided`` the mesh has every face twice (both windings) and each distinct
    contact point gets a random one of the two opposite normals, as a tie-break would."""
    rng = np.random.default_rng(seed)
    box = trimesh.creation.box(extents=2 * HALF)
    if two_sided:
        faces = np.concatenate([box.faces[:, ::-1], box.faces])
        box = trimesh.Trimesh(box.vertices, faces, process=False)
    mesh_path = tmp_path / "box.obj"
    box.export(mesh_path)

    # a pool of points shared between pairs (as single grasps are shared in the release)
    pool = []
    for _ in range(12):
        axis = int(rng.integers(3))
        p, n = _face_point(rng, axis, 1.0)
        q = p.copy()
        q[axis] = -q[axis]  # the opposite finger on the opposite face
        pool.append((p, n, q, -n))
    sign = {}
    points = np.zeros((N_PAIRS, 4, 3))
    normals = np.zeros((N_PAIRS, 4, 3))
    for i in range(N_PAIRS):
        a, b = rng.choice(len(pool), size=2, replace=False)
        for arm, g in enumerate((a, b)):
            p, n, q, m = pool[g]
            points[i, 2 * arm], points[i, 2 * arm + 1] = p, q
            for k, (pt, nn) in enumerate(((p, n), (q, m))):
                key = tuple(pt)
                if key not in sign:
                    sign[key] = rng.choice([-1.0, 1.0]) if two_sided else 1.0
                normals[i, 2 * arm + k] = sign[key] * nn
    result = evaluate(points, normals, convention=convention, loss_rtol=1e-7)
    grasps = np.tile(np.eye(4), (N_PAIRS, 2, 1, 1))
    grasps[:, :, :3, 3] = points.reshape(N_PAIRS, 2, 2, 3).mean(axis=2)
    loss = np.nan_to_num(result.loss, nan=1e3)
    data = io.DualGraspSet(
        grasps=grasps,
        contact_points=points,
        contact_forces=result.forces,
        loss_values=loss,
        passing_indices=np.flatnonzero(result.passed),
        failed_indices=np.flatnonzero(~result.passed),
        object_file="box.obj",
        object_scale=1.0,
    )
    h5_path = tmp_path / "box.h5"
    io.write_dg16m(h5_path, data)
    return h5_path, mesh_path, normals


def _tamper(path: Path, **changes: object) -> None:
    """Rewrite the file at ``path`` with some of its DualGraspSet fields replaced."""
    io.write_dg16m(path, dataclasses.replace(io.read_dg16m(path), **changes))


# --------------------------------------------------------------------------------------------
# Synthetic files
# --------------------------------------------------------------------------------------------


def test_synthetic_file_agrees_fully(tmp_path: Path) -> None:
    h5, mesh, _ = _box_file(tmp_path)
    report = verify_file(h5, mesh)
    assert 0 < report.stored_passing < report.pairs  # both verdicts are exercised
    assert report.agreement == 1.0
    assert report.agreement_full == 1.0
    assert report.disagreements == []
    assert report.contacts["ambiguous_points"] == 0
    assert report.contacts["max_distance_m"] < 1e-12
    assert report.stored_forces["pairs_outside_cones"] == 0
    assert report.ok
    json.dumps(report.to_dict(), allow_nan=False)


def test_tampered_verdict_and_loss_are_listed(tmp_path: Path) -> None:
    h5, mesh, _ = _box_file(tmp_path)
    data = io.read_dg16m(h5)
    flipped = int(data.passing_indices[0])
    failing = int(data.failed_indices[0])
    loss = data.loss_values.copy()
    loss[failing] *= 2.0
    _tamper(
        h5,
        passing_indices=data.passing_indices[1:],
        failed_indices=np.sort(np.append(data.failed_indices, flipped)),
        loss_values=loss,
    )
    report = verify_file(h5, mesh)
    by_index = {d.index: d for d in report.disagreements}
    assert set(by_index) == {flipped, failing}
    assert by_index[flipped].kind == "verdict"
    assert "contradicts the stored loss" in by_index[flipped].reason
    assert by_index[failing].kind == "loss"
    assert by_index[failing].reason.startswith("stored loss")
    assert report.agreement == pytest.approx(1 - 1 / N_PAIRS)
    assert report.fail_to_pass == 1
    assert not report.ok
    assert [d.index for d in report.unexplained] == sorted(by_index)
    assert f"    {flipped}: stored fail" in report.format_text()


def test_two_sided_mesh_is_resolved_by_face_choice(tmp_path: Path) -> None:
    h5, mesh, _ = _box_file(tmp_path, two_sided=True, seed=1)
    report = verify_file(h5, mesh)
    assert report.contacts["two_sided_points"] == report.contacts["distinct_points"]
    assert report.disagreements  # trimesh's tie-break differs from the file's at some points
    assert report.resolved_agreement_full == 1.0
    assert all(d.explained for d in report.disagreements)
    assert report.consistent is not None
    assert report.consistent["agreement_full"] == 1.0
    assert report.stored_forces["pairs_outside_cones"] == 0


def test_file_normals_are_used_when_stored(tmp_path: Path) -> None:
    h5, mesh, normals = _box_file(tmp_path, two_sided=True, seed=1)
    _tamper(h5, extras={"contact_normals": normals})
    report = verify_file(h5, mesh)
    assert report.normals_source == "file"
    assert report.agreement_full == 1.0
    assert report.contacts["file_normals_matching_a_face"] == 4 * N_PAIRS


def test_wrong_mesh_is_a_clear_error(tmp_path: Path) -> None:
    h5, _, _ = _box_file(tmp_path)
    other = tmp_path / "sphere.obj"
    trimesh.creation.icosphere(radius=0.5).export(other)
    with pytest.raises(MeshError, match="does not match") as info:
        verify_file(h5, other)
    assert "median distance" in str(info.value)
    with pytest.raises(MeshError, match="no such file"):
        verify_file(h5, tmp_path / "missing.obj")
    with pytest.raises(Dg16mError, match="convention"):
        verify_file(h5, other, convention="upside-down")


# --------------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------------


def test_cli_prints_agreement_and_writes_json(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    h5, mesh, _ = _box_file(tmp_path)
    out = tmp_path / "report" / "verify.json"
    assert main(["verify", str(h5), "--mesh", str(mesh), "--json", str(out), "--strict"]) == 0
    text = capsys.readouterr().out
    assert "agreement        100.00% of verdicts" in text
    report = json.loads(out.read_text())
    assert report["pairs"] == N_PAIRS
    assert report["agreement"] == 1.0
    assert report["unexplained"] == []


def test_cli_strict_and_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    h5, mesh, _ = _box_file(tmp_path)
    data = io.read_dg16m(h5)
    loss = data.loss_values.copy()
    loss[data.failed_indices[0]] += 5.0
    _tamper(h5, loss_values=loss)
    assert main(["verify", str(h5), "--mesh", str(mesh)]) == 0
    assert main(["verify", str(h5), "--mesh", str(mesh), "--strict"]) == 1
    capsys.readouterr()
    assert main(["verify", str(h5), "--mesh", str(tmp_path / "nope.obj")]) == 2
    assert "dg16m verify: error:" in capsys.readouterr().err


def test_cli_help_has_examples(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(["verify", "--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert "examples:" in out
    assert "dg16m verify" in out


# --------------------------------------------------------------------------------------------
# The real release file
# --------------------------------------------------------------------------------------------


@pytest.mark.real_data
def test_release_airplane_is_reproduced(real_data: Path) -> None:
    report = verify_file(
        real_data / "dg16m_airplane.h5",
        real_data / "dg16m_airplane.obj",
        convention="release",
    )
    assert report.pairs == 4000
    assert report.agreement >= 0.97
    # every contact lies on two coincident opposite faces: trimesh's tie-break is arbitrary
    assert report.contacts["two_sided_points"] == report.contacts["distinct_points"]
    # no stored failure is judged passing once the face choice at ambiguous contacts is free
    assert report.resolved_fail_to_pass == 0
    assert not report.unexplained
    # one face per distinct contact point reproduces every verdict (and loss)
    assert report.consistent is not None
    assert report.consistent["agreement"] == 1.0
    assert not report.convention_suspect
    # the stored forces are the release's optimal forces: their residual is the stored loss
    assert report.stored_forces["residual_vs_loss_max_abs_passing"] < 1e-9
    assert report.stored_forces["pairs_outside_cones"] == 0
    assert report.ok


@pytest.mark.real_data
def test_release_airplane_with_the_physical_convention_is_flagged(real_data: Path) -> None:
    # On a two-sided mesh flipping every face emulates the other convention, so per-pair face
    # choices explain everything; the number of points switched away from trimesh's face gives
    # the wrong convention away.
    report = verify_file(
        real_data / "dg16m_airplane.h5", real_data / "dg16m_airplane.obj", convention="physical"
    )
    assert report.agreement < 0.9
    assert report.convention_suspect
    assert not report.ok
    assert any("--convention release" in note for note in report.notes)
