"""Content hashes of files: the identity of a benchmark, a submission or a stored upload."""

from __future__ import annotations

import hashlib
import os

import numpy as np

_BLOCK = 1 << 20


def file_sha256(path: str | os.PathLike[str]) -> str:
    """Hex sha256 of a file's bytes, read in 1 MiB blocks (any size, bounded memory)."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        while block := handle.read(_BLOCK):
            digest.update(block)
    return digest.hexdigest()


def mesh_sha256(vertices: np.ndarray, faces: np.ndarray) -> str:
    """Hex sha256 of a mesh's arrays as read from its file: (V, 3) vertices as little-endian
    float64 and (F, 3) faces as little-endian int64, with their shapes (the identity of a
    benchmark object's mesh: equal arrays, equal hash, on any machine)."""
    vertices = np.ascontiguousarray(vertices, dtype="<f8")
    faces = np.ascontiguousarray(faces, dtype="<i8")
    digest = hashlib.sha256(f"dg16m-mesh:{vertices.shape}:{faces.shape}:".encode())
    digest.update(vertices.tobytes())
    digest.update(faces.tobytes())
    return digest.hexdigest()
