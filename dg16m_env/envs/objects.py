"""The benchmark objects an environment draws from, with their compiled scenes cached.

:class:`BenchmarkObjects` reads a benchmark file once (default: the one shipped with dg16m),
lazily: the index (ids, rows, labels) at construction, each object's parts and carried mesh when
the object is first used (``read_benchmark(..., lazy=True)``), so making an environment on the
300-object real benchmark costs what the procedural one does. It draws an object with the
environment's generator (or takes ``options={"object_id": ...}``), and keeps the loaded objects,
compiled trial scenes and observations (shared by every environment of the process on the same
benchmark), so resetting onto an object again costs nothing. Cached values are shared: do not
modify them.

:func:`split_objects` is the train / held-out rule of every learning baseline and of the Lift
demonstrations (:mod:`dg16m_env.envs.lift.demos`): every third object held out.
"""

from __future__ import annotations

import os
from collections import OrderedDict
from collections.abc import Sequence
from typing import Any

import numpy as np

from dataset_gen.objects.grasp_object import GraspObject
from dg16m_env.benchmark.model import BenchmarkParameters
from dg16m_env.benchmark.ref import BenchmarkRef, load_benchmark_ref
from dg16m_env.physics.scene import Scene, compile_scene
from dg16m_env.subjects.observation import object_observation

CACHE_SIZE = 512
"""Objects whose compiled scene / loaded object / observation are kept (least recently used
out first): every object of the shipped benchmark (about 92 MB for its 300), so an environment
loads and compiles each object once."""


def split_objects(object_ids: Sequence[str]) -> tuple[list[str], list[str]]:
    """``(train, held_out)``: every third object held out (``object_ids[::3]``, in benchmark
    order, so each procedural family is on both sides), the rest for training, both in the
    order given.

    On the shipped procedural benchmark (300 objects): 200 training and 100 held-out objects.
    """
    held_out = list(object_ids[::3])
    held = set(held_out)
    return [i for i in object_ids if i not in held], held_out


class BenchmarkObjects:
    """The objects of a benchmark an environment resets onto.

    Args:
        benchmark: benchmark file or reference (default: the shipped benchmark).
        object_ids: draw only among these (default: every object of the benchmark).
        mesh_root: folder of a mesh benchmark's meshes.

    Raises:
        ValueError: an unknown id or a bad file (an ``EvaluatorError`` or a ``BenchmarkError``).
    """

    def __init__(
        self,
        benchmark: str | os.PathLike[str] | BenchmarkRef | None = None,
        object_ids: Sequence[str] | None = None,
        mesh_root: str | os.PathLike[str] | None = None,
    ) -> None:
        # Lazy: only the index is read here; an object's parts and mesh when it is first used.
        self.ref = load_benchmark_ref(benchmark, mesh_root, lazy=True)
        known = self.ref.object_ids
        ids = list(known) if object_ids is None else [str(i) for i in object_ids]
        unknown = sorted(set(ids) - set(known))
        if unknown or not ids:
            raise ValueError(
                f"object_ids: expected ids of the benchmark's {len(known)} objects (e.g. "
                f"{known[0]!r}), found {unknown[:3] if unknown else 'none'}"
            )
        self.object_ids = ids
        self.parameters: BenchmarkParameters = self.ref.benchmark.parameters()
        # Shared by every BenchmarkObjects of this process on the same benchmark file (vector
        # environments in one process load each object once; see _SHARED).
        key = (self.ref.sha256, str(self.ref.mesh_root))
        if key not in _SHARED:
            _SHARED[key] = (OrderedDict(), OrderedDict(), OrderedDict())
        self._objects, self._scenes, self._observations = _SHARED[key]

    def choose(self, rng: np.random.Generator, object_id: str | None = None) -> str:
        """An object id: ``object_id`` when given (checked), else one drawn uniformly."""
        if object_id is None:
            return self.object_ids[int(rng.integers(len(self.object_ids)))]
        if object_id not in self.ref.object_ids:
            raise ValueError(
                f"options['object_id']: expected an id of the benchmark (e.g. "
                f"{self.object_ids[0]!r}), found {object_id!r}"
            )
        return object_id

    def benchmark_object(self, object_id: str) -> Any:
        """The :class:`~dg16m_env.benchmark.model.BenchmarkObject` of ``object_id``."""
        return self.ref.benchmark.objects[self.ref.object_ids.index(object_id)]

    def rows(self, object_id: str) -> np.ndarray:
        """The benchmark rows (candidate dual grasps) of ``object_id``."""
        return self.ref.benchmark.object_rows(object_id)

    def load(self, object_id: str) -> GraspObject:
        """The object (object frame), cached."""
        return _cached(
            self._objects,
            object_id,
            lambda: self.benchmark_object(object_id).load(self.ref.mesh_root),
        )

    def scene(self, object_id: str) -> Scene:
        """The compiled trial scene (:func:`dg16m_env.physics.scene.compile_scene`) with the
        benchmark's stored parts, mass and scene parameters, cached."""

        def build() -> Scene:
            stored = self.benchmark_object(object_id)
            return compile_scene(
                self.load(object_id), params=self.parameters.scene, parts=stored.parts
            )

        return _cached(self._scenes, object_id, build)

    def observation(self, object_id: str, n_points: int, seed: int) -> dict[str, Any]:
        """The object's observation (:func:`dg16m_env.subjects.observation.object_observation`), cached;
        do not modify it."""
        return _cached(
            self._observations,
            (object_id, n_points, seed),
            lambda: object_observation(self.load(object_id), n_points=n_points, seed=seed),
        )


_SHARED: dict[tuple[str, str], tuple[OrderedDict, OrderedDict, OrderedDict]] = {}
"""Per process and benchmark (sha256, mesh folder): the loaded objects, compiled scenes and
observations, each at most :data:`CACHE_SIZE`. Sharing them keeps memory flat for vector
environments and bounds how many ray-cast scenes (trimesh / Embree) a process ever builds: with
embreex 4.4 and torch in one process, building a few thousand of them crashed (see
BENCHMARKS.md)."""


def _cached(cache: OrderedDict, key: Any, build: Any) -> Any:
    if key in cache:
        cache.move_to_end(key)
        return cache[key]
    value = build()
    cache[key] = value
    while len(cache) > CACHE_SIZE:
        cache.popitem(last=False)
    return value
