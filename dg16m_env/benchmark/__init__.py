"""The benchmark layer: a benchmark's model, its file, where its objects come from, how it is built,
the shipped benchmarks by short name, reports, and the real-object source.

Layer rule: modules here import :mod:`dg16m_env.physics` and :mod:`dg16m_env.rates` (and
:mod:`dataset_gen`), never a layer above (subjects, evaluators, envs, cli).

========================  ====================================================================
module                    what lives there
========================  ====================================================================
:mod:`.model`             :class:`Benchmark` (rows, objects, parameters), the arms, errors
:mod:`.file`              the HDF5 file: its schema, :func:`read_benchmark`, :func:`write_benchmark`
:mod:`.names`             shipped benchmarks by short name (``"procedural"``, ``"real"``)
:mod:`.ref`               :class:`BenchmarkRef`: a loaded benchmark and its sha256
:mod:`.sources`           where objects come from (procedural split, meshes, DG16M files)
:mod:`.arms`              the pairs an object gives (the paper's arms, a file's pairs), the screen
:mod:`.build`             building: one object, budgets and limits, resumable builds
:mod:`.report`            the report of a benchmark (:mod:`.report_text`, :mod:`.report_plot`)
:mod:`.real`              the real-object benchmark (Sweet Home 3D furniture) and its split
:mod:`.real_build_state`  the state of a real-object build (what is done, what failed)
========================  ====================================================================

The public names of these modules (those of the former ``dg16m_env.benchmark`` module and
:class:`BenchmarkRef`) are also importable from this package (``from dg16m_env.benchmark
import read_benchmark``); each is imported on first use, so reading a benchmark file does not
import the builder.

The simulation benchmark: dual grasps on fixed objects, each labelled by a success probability.

Building (``dg16m benchmark build``)
------------------------------------
For each object of the procedural ``benchmark`` split (300 objects, 10 families x 30), of a
folder of the user's meshes (``--meshes DIR``: each mesh file is an object, in metres unless
``--scale``; real meshes are simulated through their CoACD convex parts,
:func:`dataset_gen.objects.decomposition.object_parts`), or of the user's meshes with DG16M grasp files
(``--grasps``: a folder of ``<id>.h5`` or a folder written by ``dg16m generate``, which holds
``grasps/<id>.h5`` and, for procedural objects, ``meshes/``):

1. sample :attr:`BenchmarkParameters.n_grasps` antipodal single-arm grasps (Panda hand);
2. pair them like the generator (``PAPER.min_center_distance`` centre pruning, gripper-gripper
   collision: the *candidates*) and check force closure; draw the paper's four arms
   (Table III, :data:`SOURCES`): up to ``n_passing`` force-closure-passing candidates
   (``fc_pass``), ``n_failing`` failing candidates whose loss is proven above
   ``PAPER.failing_min_loss`` (``fc_fail``, as the release keeps them; a shortfall of passing
   pairs is filled from them), ``n_random`` pairs drawn uniformly among the candidates
   (``random``, the paper's random dual-arm pairs) and ``n_farthest`` of the pairs that join each
   grasp to the grasp whose centre is farthest from it (``farthest``, the paper's diametrically
   opposite pairing). With a DG16M file instead, draw its stored passing / failing pairs
   (:func:`choose_file_pairs`) and move their poses from the file's gripper to the Panda hand
   (:func:`retarget_poses`). Optionally (``BenchmarkSource.reseat_max`` > 0, ``--reseat``:
   meant for DG16M files whose poses were made for another gripper) re-seat the hands
   (:mod:`dg16m_env.physics.reseat`): a hand whose open palm or fingers penetrate the object's convex
   parts deeper than the protocol's ``invalid_penetration`` is moved back along its approach
   axis in 1 mm steps up to ``reseat_max`` until it clears; a hand that cannot clear stays (its
   trial is invalid and counts as a failure, the row is kept). Re-seating changes the grasp
   (the stored contacts stay the file's): every hand's shift is stored
   (``grasps/reseat_shift``) and how many moved, and how far, is always reported;
3. label every pair with its success probability (:mod:`dg16m_env.physics.labels`): the trial protocol
   (:mod:`dg16m_env.physics.trial`) at the nominal pose and at K seeded perturbations of it, at two
   levels (held through every disturbance; held under gravity).

Objects are independent tasks (process pool or Ray); each finished object is written to
``OUT/objects/<id>.h5`` and recorded in ``OUT/manifest.json``, so an interrupted build resumes.
The last step concatenates them, in the order of the object list, into ``OUT/benchmark.h5``.
Results do not depend on the number of workers or the backend.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS: dict[str, str] = {
    "FORMAT": "model",
    "SCHEMA_VERSION": "model",
    "BENCHMARK_FILE": "model",
    "OBJECTS_FOLDER": "model",
    "SOURCES": "model",
    "ARMS": "model",
    "FLOAT_SIM": "model",
    "BenchmarkError": "model",
    "BenchmarkParameters": "model",
    "BenchmarkObject": "model",
    "Benchmark": "model",
    "concatenate": "model",
    "hand_line_distance": "model",
    "write_benchmark": "file",
    "MAX_DECIMALS": "file_lazy",
    "read_benchmark": "file",
    "same_bits": "file",
    "grid_multiples": "file",
    "on_grid": "file_lazy",
    "BenchmarkSource": "sources",
    "retarget_poses": "sources",
    "file_gripper": "sources",
    "file_poses": "sources",
    "procedural_benchmark_sources": "sources",
    "read_split": "sources",
    "split_id": "sources",
    "mesh_benchmark_sources": "sources",
    "grasp_folders": "sources",
    "file_benchmark_sources": "sources",
    "sampled_pairs": "arms",
    "choose_file_pairs": "arms",
    "ObjectRejectedError": "arms",
    "screen_passing": "arms",
    "grid_parts": "build",
    "benchmark_object": "build",
    "benchmark_metadata": "build",
    "BuildLimits": "build",
    "build_benchmark": "build",
    "build_parameters": "build",
    "build_objects": "build",
    "write_built_benchmark": "build",
    "EMBEDDED_BENCHMARK": "names",
    "REAL_BENCHMARK": "names",
    "SHIPPED_BENCHMARKS": "names",
    "SHIPPED_MUJOCO_VERSION": "names",
    "benchmark_file": "names",
    "BenchmarkRef": "ref",
    "load_benchmark_ref": "ref",
}
"""Public name -> the module of this package that defines it."""

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
