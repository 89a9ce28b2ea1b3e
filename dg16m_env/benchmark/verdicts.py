"""Why a benchmark build rejected an object, in words and in its manifest entry: a stage past
its CPU budget or the wall-time safety net (:func:`timeout_verdict`), a child that crashed
(:func:`crash_verdict`), too few passing pairs; and which rejections a resumed build keeps
(:func:`kept_rejections`: unchanged inputs and settings, a verdict that does not depend on
machine load). Used by :mod:`dg16m_env.benchmark.build`.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dataset_gen.io import read_manifest
from dg16m_core.budget import WALL_FACTOR, StageCrashError, StageTimeoutError, signal_words
from dg16m_core.errors import Dg16mError
from dg16m_env.benchmark.arms import ObjectRejectedError
from dg16m_env.benchmark.sources import BenchmarkSource

STAGE_WORDS = {
    "start": "starting the worker process",
    "load": "loading the mesh",
    "screen": "the screening (grasps sampled on the mesh and paired)",
    "decompose": "its convex decomposition (CoACD)",
    "sample": "sampling grasps and pairing them",
    "label": "its MuJoCo trials",
}
"""Each stage of :func:`~dg16m_env.benchmark.build.benchmark_object` in words, for verdicts."""

STAGE_ADVICE = {
    "decompose": "the mesh is too detailed or thin-walled for the decomposition; simplify it "
    "(fewer faces, thicker walls)",
    "label": "an object of very many convex parts makes every trial slow; a coarser mesh helps",
    "screen": "a mesh of very many faces makes sampling slow; simplify it",
    "sample": "a mesh of very many faces or convex parts makes sampling slow; simplify it",
}

CRASH_ADVICE = {
    "decompose": "CoACD fails on this mesh; try a coarser or thicker mesh (`dg16m objects "
    "repair FILE` with fewer --target-faces or a larger --pitch-fraction) or see which "
    "decomposition settings end (`dg16m objects decompose FILE --preprocess on` or another "
    "--threshold)",
    "label": "MuJoCo fails on this object's convex parts; a coarser mesh (fewer faces, fewer "
    "parts) may avoid it",
}
"""What to do after a crash in each stage (others: :data:`CRASH_DEFAULT_ADVICE`)."""

CRASH_DEFAULT_ADVICE = (
    "a crash in compiled code or out of memory; a coarser mesh (fewer faces) may avoid it"
)
"""What to do after a crash in a stage :data:`CRASH_ADVICE` does not name."""

RELOAD_LIMITS = ("wall", "object")
"""The limits whose verdicts depend on machine load: a resumed build redoes those objects."""


def _budget_option(stage: str) -> str:
    return "sample" if stage == "screen" else stage


def timeout_verdict(exc: StageTimeoutError) -> str:
    """A stopped stage in words: which limit ended it (the CPU budget, the wall-time safety
    net or the object's wall bound), the CPU seconds it had used, and what to do."""
    what = STAGE_WORDS.get(exc.stage, f"stage {exc.stage!r}")
    cpu = getattr(exc, "cpu_seconds", None)
    used = "" if cpu is None else f" after {cpu:.1f} CPU s"
    if exc.whole:
        return (
            f"the object did not end within its bound of {exc.budget:g} s of wall time (stopped "
            f"in {what}{used}): a loaded machine or a slow object; retry on a quieter machine or "
            "raise the bound"
        )
    if getattr(exc, "wall_s", None) is not None:
        only = f" after only {cpu:.1f} CPU s" if cpu is not None else ""
        return (
            f"{what} was stopped by the wall-time safety net of {exc.wall_s:g} s "
            f"({WALL_FACTOR:g} x its budget of {exc.budget:g} CPU s){only}: "
            "a heavily loaded machine or a stage that waits; rerun on a quieter machine (a "
            "resumed build redoes it)"
        )
    advice = STAGE_ADVICE.get(exc.stage, "")
    raise_it = f"raise its budget with --stage-budget {_budget_option(exc.stage)}=SECONDS"
    head = (
        f"{what} did not end within its budget of {exc.budget:g} CPU s"
        if cpu is None
        else f"{what} used {cpu:.1f} CPU s, past its budget of {exc.budget:g} CPU s"
    )
    return f"{head}: {advice}, or {raise_it}" if advice else f"{head}: {raise_it}"


def crash_verdict(exc: StageCrashError, fallback: Mapping[str, Any] | None = None) -> str:
    """A crashed stage in words: the signal or exit status, the CPU seconds used, what the
    fallback did (``fallback``: an entry's ``decompose_fallback``) and what to do."""
    what = STAGE_WORDS.get(exc.stage, f"stage {exc.stage!r}")
    how = (
        f"with {signal_words(exc.signal)}"
        if exc.signal is not None
        else f"(exit status {exc.exit_code}, no answer)"
    )
    used = "" if exc.cpu_seconds is None else f" after {exc.cpu_seconds:.1f} CPU s"
    tried = ""
    if fallback is not None:
        tried = (
            f"; tried again with {fallback['settings']}: {fallback['outcome']}"
            if fallback.get("tried")
            else f"; no fallback: {fallback['outcome']}"
        )
    advice = CRASH_ADVICE.get(exc.stage, CRASH_DEFAULT_ADVICE)
    return f"{what} crashed {how}{used}{tried}; {advice}"


def seconds(times: Mapping[str, float]) -> dict[str, float]:
    return {k: round(float(v), 1) for k, v in times.items()}


def input_digest(item: BenchmarkSource) -> str:
    """The sha256 of what one object is built from: its mesh and grasp files' bytes (or its
    mesh arrays) and its source settings (scale, size check, family and seed, grasp gripper,
    re-seating). A rejection is kept across resumes while it is unchanged (:func:`kept_rejections`).

    Raises:
        OSError: a file cannot be read.
    """
    source = item.source
    digest = hashlib.sha256()
    settings = {
        "object_id": item.object_id,
        "family": source.family,
        "family_seed": source.family_seed,
        "scale": source.scale,
        "allow_any_size": source.allow_any_size,
        "grasp_gripper": item.grasp_gripper,
        "reseat_max": item.reseat_max,
    }
    digest.update(json.dumps(settings, sort_keys=True, default=str).encode())
    for path in (source.mesh, item.grasp_file):
        digest.update(b"\0" if path is None else Path(path).read_bytes())
    if source.mesh_arrays is not None:
        for array in source.mesh_arrays:
            digest.update(np.ascontiguousarray(array).tobytes())
    return digest.hexdigest()


def rejection_entry(item: BenchmarkSource, exc: Dg16mError) -> dict[str, Any]:
    """The manifest entry of an object rejected by ``exc`` (a budget, a crash, too few pairs)."""
    fallback = getattr(exc, "fallback", None)
    entry: dict[str, Any] = {"status": "failed", "files": {}, "stage": getattr(exc, "stage", "")}
    if isinstance(exc, StageTimeoutError):
        entry.update(
            error=f"{item.object_id}: {exc}",
            rejected="time budget",
            verdict=timeout_verdict(exc),
            limit=exc.limit,
        )
    elif isinstance(exc, StageCrashError):
        entry.update(
            error=f"{item.object_id}: {exc}",
            rejected="crashed",
            verdict=crash_verdict(exc, fallback),
        )
        entry.update({"signal": exc.signal} if exc.signal is not None else {})
        entry.update({"exit_code": exc.exit_code} if exc.signal is None else {})
    else:
        assert isinstance(exc, ObjectRejectedError)
        entry.update(error=str(exc), rejected="too few passing pairs", verdict=exc.verdict)
    if not entry["verdict"]:
        del entry["verdict"]
    if getattr(exc, "cpu_seconds", None) is not None:
        entry["cpu_seconds"] = round(float(exc.cpu_seconds), 1)  # type: ignore[attr-defined]
    if fallback is not None:
        entry["decompose_fallback"] = fallback
    if getattr(exc, "stage_times", None):  # set by run_with_budget
        entry["stage_seconds"] = seconds(exc.stage_times)  # type: ignore[attr-defined]
    with contextlib.suppress(OSError):  # unreadable now: the rejection is not kept on resume
        entry["input_sha256"] = input_digest(item)
    return entry


def kept_rejections(
    root: Path, items: Sequence[BenchmarkSource], parameters: Mapping[str, Any]
) -> dict[str, dict[str, Any]]:
    """The objects of ``items`` that ``root``'s manifest already rejected and a resumed build
    keeps, by id: a manifest of a benchmark build with the same ``parameters``, an entry with
    a ``rejected`` reason whose ``input_sha256`` is the object's :func:`input_digest` now, and
    a verdict that does not depend on load (not a wall-time limit, :data:`RELOAD_LIMITS`).
    Entries written before the digest existed are redone once."""
    if not (Path(root) / "manifest.json").is_file():
        return {}
    try:
        manifest = read_manifest(root)
    except Dg16mError:  # the build refuses it with its own message
        return {}
    if manifest.get("kind") != "benchmark" or manifest.get("parameters") != parameters:
        return {}
    kept = {}
    for item in items:
        entry = manifest["entries"].get(item.object_id) or {}
        if (
            entry.get("status") == "failed"
            and entry.get("rejected")
            and entry.get("limit") not in RELOAD_LIMITS
            and entry.get("input_sha256")
        ):
            try:
                unchanged = entry["input_sha256"] == input_digest(item)
            except OSError:
                unchanged = False
            if unchanged:
                kept[item.object_id] = entry
    return kept
