"""Reading a benchmark file's objects on demand (``read_benchmark(path, lazy=True)``) and the
checked dataset reads and stored-coordinate encodings the eager reader
(:mod:`dg16m_env.benchmark.file`) shares with it. The file schema is in that module's docstring."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from dataset_gen.objects.grasp_object import ConvexPart, part_from_dict
from dg16m_core.errors import Dg16mError
from dg16m_core.hashing import mesh_sha256
from dg16m_env.benchmark.model import BenchmarkError, BenchmarkObject

MAX_DECIMALS = 9


def from_decimals(multiples: np.ndarray, decimals: int) -> np.ndarray:
    """(V, 3) integers -> (V, 3) float64 ``multiples / 10**decimals`` (m): correctly rounded,
    so equal to the float an OBJ file's decimal text parses to."""
    return np.asarray(multiples, dtype=np.int64).astype(np.float64) / 10.0**decimals


def on_grid(multiples: np.ndarray, grid: float) -> np.ndarray:
    """(V, 3) integer multiples of ``grid`` (m) -> (V, 3) float64 vertices (m); the one
    formula both the build and the reader use, so stored hulls are the simulated ones."""
    return np.asarray(multiples, dtype=np.int64).astype(np.float64) * grid


def checked_dataset(
    f: h5py.File, path: Path, key: str, shape: tuple[int | None, ...], kinds: str
) -> h5py.Dataset:
    """Like ``read_checked``, without reading the data."""
    if key not in f:
        raise BenchmarkError(f"{path}: expected dataset {key!r}, found it missing")
    ds = f[key]
    if (
        ds.dtype.kind not in kinds
        or ds.ndim != len(shape)
        or any(want is not None and got != want for got, want in zip(ds.shape, shape, strict=True))
    ):
        raise BenchmarkError(
            f"{path}: {key}: expected shape {shape} of kind {kinds!r}, found {ds.shape} {ds.dtype}"
        )
    return ds


def read_checked(
    f: h5py.File, path: Path, key: str, shape: tuple[int | None, ...], kinds: str
) -> np.ndarray:
    """The values of dataset ``key``, once its shape (None: any length) and dtype kind (one of
    ``kinds``) are checked (:func:`checked_dataset`)."""
    return checked_dataset(f, path, key, shape, kinds)[()]


class LazyReader:
    """What :func:`~dg16m_env.benchmark.file.read_benchmark` (``lazy=True``) keeps of a file to read one object's parts and
    carried mesh later: the index of the stored hulls and meshes (counts, hashes, encodings),
    and the file's size and modification time (a changed file is refused). Picklable.

    Attributes:
        reads: object indices read so far, in order (each once: the object keeps what it read).
    """

    def __init__(self, f: h5py.File, path: Path, parts_json: list[str]) -> None:
        o = len(parts_json)
        self.path = path
        stat = path.stat()
        self.stamp = (stat.st_size, stat.st_mtime_ns)
        self.parts_json = parts_json
        self.reads: list[int] = []
        # Hulls (objects/hull_*): per object, its first hull and hull count; hull vertex rows.
        self.hull_first = np.zeros(o + 1, dtype=np.int64)
        self.hull_starts = np.zeros(1, dtype=np.int64)
        self.hull_grid: float | None = None
        if "objects/hull_objects" in f:
            per_object = read_checked(f, path, "objects/hull_objects", (o,), "i")
            counts = read_checked(f, path, "objects/hull_counts", (int(per_object.sum()),), "i")
            vertices = checked_dataset(f, path, "objects/hull_vertices", (None, 3), "fi")
            if vertices.dtype.kind == "i":
                grid = vertices.attrs.get("grid_m")
                if grid is None or not np.isfinite(grid) or not float(grid) > 0:
                    raise BenchmarkError(
                        f"{path}: objects/hull_vertices: expected integer multiples with a "
                        f"positive 'grid_m' attribute (m), found grid_m {grid!r}"
                    )
                self.hull_grid = float(grid)
            if (
                per_object.min(initial=0) < 0
                or counts.min(initial=4) < 4
                or counts.sum() != vertices.shape[0]
            ):
                raise BenchmarkError(
                    f"{path}: objects/hull_counts: expected counts >= 4 summing to the "
                    f"{vertices.shape[0]} hull vertices stored, found sum {int(counts.sum())}"
                )
            self.hull_first = np.concatenate([[0], np.cumsum(per_object, dtype=np.int64)])
            self.hull_starts = np.concatenate([[0], np.cumsum(counts, dtype=np.int64)])
        # Carried meshes (objects/mesh_*): per object, its first vertex and face.
        self.mesh_counts = np.zeros((o, 2), dtype=np.int64)
        self.mesh_decimals: int | None = None
        self.negative_zeros = np.zeros(0, dtype=np.int64)
        self.mesh_hashes = [""] * o
        if "objects/mesh_counts" in f:
            counts = read_checked(f, path, "objects/mesh_counts", (o, 2), "i")
            vertices = checked_dataset(f, path, "objects/mesh_vertices", (None, 3), "fi")
            faces = checked_dataset(f, path, "objects/mesh_faces", (None, 3), "i")
            if vertices.dtype.kind == "i":
                decimals = vertices.attrs.get("decimals")
                if decimals is None or not 0 <= int(decimals) <= MAX_DECIMALS:
                    raise BenchmarkError(
                        f"{path}: objects/mesh_vertices: expected integer multiples with a "
                        f"'decimals' attribute in [0, {MAX_DECIMALS}], found decimals {decimals!r}"
                    )
                self.mesh_decimals = int(decimals)
                if "objects/mesh_negative_zeros" in f:
                    zeros = read_checked(f, path, "objects/mesh_negative_zeros", (None,), "i")
                    size = 3 * vertices.shape[0]
                    if zeros.size and (zeros.min() < 0 or zeros.max() >= size):
                        raise BenchmarkError(
                            f"{path}: objects/mesh_negative_zeros: expected flat indices in "
                            f"[0, {size}), found [{zeros.min()}, {zeros.max()}]"
                        )
                    self.negative_zeros = zeros.astype(np.int64)
            hashes = read_checked(f, path, "objects/mesh_sha256", (o,), "OS")
            self.mesh_hashes = [s.decode() for s in hashes]
            if (
                counts.min(initial=0) < 0
                or counts[:, 0].sum() != vertices.shape[0]
                or counts[:, 1].sum() != faces.shape[0]
            ):
                raise BenchmarkError(
                    f"{path}: objects/mesh_counts: expected counts summing to the "
                    f"{vertices.shape[0]} vertices and {faces.shape[0]} faces stored, found "
                    f"sums {counts.sum(axis=0).tolist()}"
                )
            self.mesh_counts = counts.astype(np.int64)
        self.mesh_first = np.concatenate(
            [np.zeros((1, 2), dtype=np.int64), np.cumsum(self.mesh_counts, axis=0)]
        )

    def n_parts(self, i: int) -> int:
        """Object ``i``'s number of parts, without reading them."""
        return len(json.loads(self.parts_json[i])) + int(
            self.hull_first[i + 1] - self.hull_first[i]
        )

    def has_mesh(self, i: int) -> bool:
        return bool(self.mesh_counts[i, 0] > 0)

    def read(
        self, i: int, object_id: str
    ) -> tuple[tuple[ConvexPart, ...], tuple[np.ndarray, np.ndarray, str] | None]:
        """Object ``i``'s parts and carried mesh (``None``), as :func:`~dg16m_env.benchmark.file.read_benchmark` reads them
        eagerly (same checks, same values).

        Raises:
            BenchmarkError: a broken part or mesh, or the file changed since it was indexed.
        """
        path = self.path
        try:
            stat = path.stat()
        except OSError as exc:
            raise BenchmarkError(f"{path}: expected the benchmark file, found: {exc}") from None
        if (stat.st_size, stat.st_mtime_ns) != self.stamp:
            raise BenchmarkError(
                f"{path}: expected the file as it was when read, found it changed since (read "
                "the benchmark again)"
            )
        try:
            parts = [part_from_dict(p) for p in json.loads(self.parts_json[i])]
        except (ValueError, TypeError, Dg16mError) as exc:
            raise BenchmarkError(f"{path}: objects/parts[{i}] ({object_id}): {exc}") from None
        first, last = int(self.hull_first[i]), int(self.hull_first[i + 1])
        mesh = None
        with h5py.File(path, "r") as f:
            if last > first:
                rows = slice(int(self.hull_starts[first]), int(self.hull_starts[last]))
                block = f["objects/hull_vertices"][rows]
                if self.hull_grid is not None:
                    block = on_grid(block, self.hull_grid)
                identity = np.eye(4)
                base = self.hull_starts[first]
                for k in range(first, last):
                    a, b = self.hull_starts[k] - base, self.hull_starts[k + 1] - base
                    try:
                        parts.append(
                            ConvexPart("mesh", identity, (), block[a:b].astype(np.float64))
                        )
                    except Dg16mError as exc:
                        raise BenchmarkError(
                            f"{path}: objects/hull_vertices, hull {k}: {exc}"
                        ) from None
            if self.has_mesh(i):
                mesh = self._read_mesh(f, i)
        self.reads.append(i)
        return tuple(parts), mesh

    def _read_mesh(self, f: h5py.File, i: int) -> tuple[np.ndarray, np.ndarray, str]:
        path = self.path
        v0, f0 = (int(x) for x in self.mesh_first[i])
        nv, nf = (int(x) for x in self.mesh_counts[i])
        raw = f["objects/mesh_vertices"][v0 : v0 + nv]
        if self.mesh_decimals is not None:
            v = from_decimals(raw, self.mesh_decimals)
            zeros = self.negative_zeros
            mine = zeros[(zeros >= 3 * v0) & (zeros < 3 * (v0 + nv))] - 3 * v0
            v.reshape(-1)[mine] = -0.0
        else:
            v = raw
        v = v.astype(np.float64)
        fc = f["objects/mesh_faces"][f0 : f0 + nf].astype(np.int64)
        if fc.size and (fc.min() < 0 or fc.max() >= nv):
            raise BenchmarkError(
                f"{path}: objects/mesh_faces of object {i}: expected indices in [0, {nv}), "
                f"found [{fc.min()}, {fc.max()}]"
            )
        digest = mesh_sha256(v, fc)
        if digest != self.mesh_hashes[i]:
            raise BenchmarkError(
                f"{path}: objects/mesh_sha256 of object {i}: expected the stored mesh to hash to "
                f"{self.mesh_hashes[i]}, found {digest} (the mesh bytes were changed)"
            )
        return v, fc, self.mesh_hashes[i]


class LazyBenchmarkObject(BenchmarkObject):
    """A :class:`~dg16m_env.benchmark.model.BenchmarkObject` of a file read with
    ``read_benchmark(path, lazy=True)``: its ``parts``, ``mesh_vertices`` and ``mesh_faces``
    are read from the file on first use and kept (:attr:`loaded` says whether they were);
    ``has_mesh`` and ``repr`` read nothing. Everything else is an ordinary benchmark object."""

    def __init__(self, reader: LazyReader, index: int, **fields: Any) -> None:
        for name, value in fields.items():
            object.__setattr__(self, name, value)
        object.__setattr__(self, "mesh_sha256", reader.mesh_hashes[index])
        object.__setattr__(self, "_reader", reader)
        object.__setattr__(self, "_index", index)
        object.__setattr__(self, "_stored", None)

    def _read(self) -> tuple[tuple[ConvexPart, ...], tuple[np.ndarray, np.ndarray, str] | None]:
        if self._stored is None:
            object.__setattr__(self, "_stored", self._reader.read(self._index, self.object_id))
        return self._stored

    @property
    def loaded(self) -> bool:
        """Whether the parts and mesh were read from the file."""
        return self._stored is not None

    @property  # type: ignore[override]
    def parts(self) -> tuple[ConvexPart, ...]:
        return self._read()[0]

    @property  # type: ignore[override]
    def mesh_vertices(self) -> np.ndarray | None:
        mesh = self._read()[1]
        return None if mesh is None else mesh[0]

    @property  # type: ignore[override]
    def mesh_faces(self) -> np.ndarray | None:
        mesh = self._read()[1]
        return None if mesh is None else mesh[1]

    @property
    def has_mesh(self) -> bool:
        return self._reader.has_mesh(self._index)

    def __repr__(self) -> str:
        origin = f"{self.family} seed {self.seed}" if self.family else f"mesh {self.file!r}"
        return (
            f"BenchmarkObject({self.object_id!r}, {origin}, scale {self.scale:.4g}, "
            f"mass {self.mass:.4g} kg, {self._reader.n_parts(self._index)} convex parts"
            f"{'' if self.loaded else ', not read yet'})"
        )
