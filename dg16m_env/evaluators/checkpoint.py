"""Per-object checkpoints of an evaluator, so that an interrupted evaluation resumes where it
stopped (``dg16m evaluate --out R.json --resume``) and gives the same bytes as an uninterrupted
run.

A checkpoint is a folder (``dg16m evaluate`` puts it beside ``--out``: ``R.json`` ->
``R.gsr.checkpoint/``) holding:

* ``run.json``: what the checkpoint is of: its format and version, the evaluator's
  :meth:`~dg16m_env.evaluators.registry.Evaluator.planned` record (name, evaluator and package
  versions, benchmark sha256 and objects, parameters, seeds) and the subject's sha256;
* one ``NNNNN.npz`` per finished object (``NNNNN`` = its index in the benchmark), holding its id
  and either its arrays or the error that made it unscorable; ``numpy.load`` reads it with
  ``allow_pickle=False``. The ``policy`` evaluator records episodes the same way (``NNNNN`` =
  the episode's index, its id ``"episode N"``).

The evaluators that checkpoint: ``gsr`` (each object's trial labels; the subject is a
submission's sha256), ``classifier`` (each object's ranking) and ``policy`` (each episode's
outcome), whose code subjects are told apart by
:func:`~dg16m_env.evaluators.code_identity.code_sha256`.

Every file is written atomically (:mod:`dg16m_core.atomic`): an interrupt leaves each object
either recorded in full or absent. Resuming refuses a checkpoint of another run
(:class:`CheckpointError` lists the differences) rather than merge it; the evaluator removes the
folder once its result is complete.
"""

from __future__ import annotations

import io
import json
import os
import shutil
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dg16m_core.atomic import write_bytes_atomic, write_json_atomic
from dg16m_core.json_values import json_ready

from .registry import EvaluatorError

FORMAT = "dg16m-evaluation-checkpoint"
VERSION = 1
RUN_FILE = "run.json"
_ID_KEY = "__object_id__"
_ERROR_KEY = "__error__"


class CheckpointError(EvaluatorError):
    """A checkpoint of another run, or a damaged one."""


def checkpoint_folder(results: str | os.PathLike[str], evaluator: str) -> Path:
    """Where ``dg16m evaluate`` keeps ``evaluator``'s checkpoint for the results file
    ``results`` (``runs/r.json`` -> ``runs/r.gsr.checkpoint``)."""
    results = Path(results)
    return results.with_name(f"{results.stem}.{evaluator}.checkpoint")


@dataclass(frozen=True)
class CheckpointRequest:
    """How an evaluator should checkpoint: into ``folder``; ``resume`` keeps what a matching
    checkpoint there holds (without it, a checkpoint there is discarded first); ``remove``: the
    evaluator removes the folder once its result is complete (``dg16m evaluate`` passes False
    and removes it after the result is written, so no interrupt falls between the two)."""

    folder: Path
    resume: bool = False
    remove: bool = True


class ObjectCheckpoint:
    """An open checkpoint of one evaluator's run over one subject (see the module docstring).

    Attributes:
        folder: the checkpoint folder.
        done: ``{object index: {"object_id": str, "error": str | None, "arrays": {name: array}}}``
            of the objects finished earlier (empty for a fresh checkpoint).
    """

    def __init__(self, request: CheckpointRequest, run: Mapping[str, Any]) -> None:
        """Open ``request.folder`` for the run described by ``run`` (JSON-ready).

        Raises:
            CheckpointError: resuming a checkpoint of another run, or a damaged one.
        """
        self.folder = Path(request.folder)
        self.remove = request.remove
        self.run = json_ready({"format": FORMAT, "version": VERSION, **dict(run)})
        self.done: dict[int, dict[str, Any]] = {}
        if request.resume and (self.folder / RUN_FILE).is_file():
            self._check_run()
            self._load()
            return
        if self.folder.exists():
            shutil.rmtree(self.folder)
        self.folder.mkdir(parents=True)
        write_json_atomic(self.folder / RUN_FILE, self.run)

    def _check_run(self) -> None:
        path = self.folder / RUN_FILE
        try:
            found = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise CheckpointError(f"{path}: expected a checkpoint record, found {exc}") from None
        if not isinstance(found, dict):
            raise CheckpointError(f"{path}: expected a JSON object, found {type(found).__name__}")
        differences = [
            f"{key} {_short(found.get(key))} (expected {_short(value)})"
            for key, value in self.run.items()
            if found.get(key) != value
        ]
        if differences:
            raise CheckpointError(
                f"--resume: expected the checkpoint {self.folder} to be of this run, found "
                f"another {'; '.join(differences)}; remove the folder or run without --resume"
            )

    def _load(self) -> None:
        for path in sorted(self.folder.glob("[0-9]*.npz")):
            try:
                index = int(path.stem)
                with np.load(path, allow_pickle=False) as data:
                    arrays = {k: data[k] for k in data.files}
            except (OSError, ValueError) as exc:
                raise CheckpointError(
                    f"{path}: expected an object's checkpoint (.npz), found {exc}; remove "
                    f"{self.folder} or run without --resume"
                ) from None
            object_id = str(arrays.pop(_ID_KEY, ""))
            error = arrays.pop(_ERROR_KEY, None)
            self.done[index] = {
                "object_id": object_id,
                "error": None if error is None else str(error),
                "arrays": arrays,
            }

    def kept(self, object_ids: list[str]) -> dict[str, dict[str, Any]]:
        """``{object id: entry}`` of the finished objects, each checked against the benchmark's
        ``object_ids`` (the index must name the same id).

        Raises:
            CheckpointError: an entry whose index and id disagree with the benchmark.
        """
        out: dict[str, dict[str, Any]] = {}
        for index, entry in self.done.items():
            expected = object_ids[index] if 0 <= index < len(object_ids) else None
            if entry["object_id"] != expected:
                raise CheckpointError(
                    f"{self.folder}: expected object {index} to be {expected!r}, found "
                    f"{entry['object_id']!r}; remove the folder or run without --resume"
                )
            out[entry["object_id"]] = entry
        return out

    def save(
        self,
        index: int,
        object_id: str,
        arrays: Mapping[str, np.ndarray] | None = None,
        error: str | None = None,
    ) -> None:
        """Record object ``index`` (``object_id``) as finished: its ``arrays``, or the ``error``
        that made it unscorable (written atomically)."""
        payload: dict[str, np.ndarray] = {_ID_KEY: np.array(object_id)}
        if error is not None:
            payload[_ERROR_KEY] = np.array(error)
        else:
            payload.update({k: np.asarray(v) for k, v in (arrays or {}).items()})
        buffer = io.BytesIO()
        np.savez(buffer, **payload)
        write_bytes_atomic(self.folder / f"{index:05d}.npz", buffer.getvalue())

    def finish(self) -> None:
        """The evaluator's result is complete: remove the checkpoint (unless its request said
        the caller does)."""
        if self.remove:
            shutil.rmtree(self.folder, ignore_errors=True)


def _short(value: Any) -> str:
    text = json.dumps(value, sort_keys=True) if value is not None else "none"
    return text if len(text) <= 60 else text[:57] + "..."
