"""Every procedural family has a feature the Panda can actually close on (contacts_from_pose)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from dataset_gen.grasps.gripper import PANDA, ContactStatus, contacts_from_pose
from dataset_gen.sources.procedural import FAMILIES, make_procedural_object


def _antipodal_candidates(
    mesh: trimesh.Trimesh, count: int, rng: np.random.Generator
) -> np.ndarray:
    """(M, 4, 4) Panda poses across thin sections: surface point, ray along -normal to the far side."""
    points, faces = trimesh.sample.sample_surface(mesh, count, seed=int(rng.integers(2**31)))
    normals = mesh.face_normals[faces]
    origins = points - 1e-5 * normals
    hits, rays, _ = mesh.ray.intersects_location(origins, -normals, multiple_hits=False)
    poses = []
    for hit, ray in zip(hits, rays, strict=True):
        width = np.linalg.norm(hit - points[ray])
        if not 0.005 < width < PANDA.max_opening - 0.005:
            continue
        base = np.cross(normals[ray], rng.normal(size=3))
        other = np.cross(normals[ray], base)
        for angle in np.linspace(0.0, 2.0 * np.pi, 6, endpoint=False):  # approaches about the axis
            approach = np.cos(angle) * base / np.linalg.norm(base) + np.sin(
                angle
            ) * other / np.linalg.norm(other)
            poses.append(PANDA.pose_from_contacts(points[ray], hit, approach))
    return np.array(poses)


@pytest.mark.parametrize("family", FAMILIES)
def test_panda_closes_on_every_family(family: str) -> None:
    obj = make_procedural_object(family, 0)
    rng = np.random.default_rng(7)
    poses = _antipodal_candidates(obj.mesh, 150, rng)
    assert len(poses) > 0, f"{family}: no section thinner than the Panda's opening"
    result = contacts_from_pose(obj, poses, gripper=PANDA)
    counts = {s.name: int((result.status == s).sum()) for s in ContactStatus}
    assert result.ok.sum() >= 3, f"{family}: {counts}"
    assert np.nanmax(result.width) < PANDA.max_opening
    # the contacts found by closing lie on the surface
    _, distance, _ = trimesh.proximity.closest_point(
        obj.mesh, result.points[result.ok].reshape(-1, 3)
    )
    assert distance.max() < 1e-6
