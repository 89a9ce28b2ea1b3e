"""Run a grasp predictor given as code (``module:callable``) in a child process, with limits.

A *predictor* is a function ``observation -> dual grasps``. It runs **only on this machine**, for
your own code: ``dg16m evaluate --predictor`` and ``dg16m submission make --predictor`` turn its
output into a submission file, and only that file (data, validated, never unpickled) is uploaded.
The leaderboard server never runs uploaded code.

Isolation model
---------------
The limits guard against mistakes (a hang, a leak, a crash), not against hostile code: the child
runs with your user's rights, sees your files and may use the network.

* ``run_predictor`` starts one child process (``multiprocessing`` "spawn", Linux). Before
  importing the target, the child sets ``RLIMIT_CORE`` to 0 and ``RLIMIT_AS`` (virtual address
  space, soft and hard) to ``memory_limit_mb`` MiB (0: no limit). The limit counts the whole
  process: the interpreter and numpy already take about 150 MiB of address space (more with many
  BLAS threads), every thread reserves its stack, and CUDA maps far more than it uses, so GPU
  predictors need ``memory_limit_mb=0``. A limit below the child's baseline is a
  :class:`PredictorError`. The child also makes itself a process group leader and asks to be killed
  when this process dies.
* The child imports the target and reports back; an import failure (module or file not found,
  missing attribute, not callable, an exception at import, ``startup_time_limit_s`` exceeded) is
  one :class:`PredictorError`, raised before any object is run.
* Each observation is sent to the child (pickled: our own data, this process to the child). The
  child writes the result to a ``.npz`` file in a private temporary folder and answers with a
  JSON message; this process never unpickles anything the child produced
  (``np.load(..., allow_pickle=False)``) and validates every array itself.
* Each call may take ``time_limit_s``; the first call of each child process may in addition use
  what the import left of ``startup_time_limit_s`` (lazy model loading, JIT warm-up). A call that
  runs over is killed with the whole child (SIGTERM, then SIGKILL), and a fresh child takes the
  remaining objects; a child that dies (segfault, ``os._exit``, the kernel's OOM killer) is
  replaced the same way. If a replacement fails to start, the remaining objects fail with that
  reason.
  An exception raised by the callable (``MemoryError`` at the address-space limit included) is
  caught in the child and becomes that object's error; the child goes on.

The observation / return contract
---------------------------------
The callable receives one object's observation, a ``dict`` with the keys of
:func:`dg16m_env.observation.object_observation` (``object_id``, ``family``, ``points`` (P, 3)
float32, ``normals`` (P, 3) float32, ``bounds`` (2, 3), ``mesh_vertices`` (V, 3),
``mesh_faces`` (F, 3); object frame, m), and returns one of

* an array (K, 2, 4, 4): K dual grasps, the two hand poses of each (Panda grasp frame -> object
  frame, m), finite rigid transforms within the bounds a submission file accepts (the
  tolerances of :mod:`dg16m_env.submission`), 1 <= K <= ``max_grasps``;
* a tuple ``(poses, scores)`` with ``scores`` (K,) finite, higher = better;
* a dict ``{"poses": poses, "scores": scores}`` (``scores`` optional).

A bare return must be an array object (numpy, or anything with ``__array__``; torch tensors are
moved to the CPU first); inside a tuple or dict, anything ``np.asarray`` takes (lists too). Float
or integer dtypes only; everything is converted to float64. A call should not depend on earlier calls: after a
timeout or a crash a fresh process (a fresh import) runs the remaining objects.

"spawn" starts the child by importing the parent's ``__main__`` module: a script that calls
:func:`run_predictor` must do so under ``if __name__ == "__main__":``.

Every failure is recorded per object in :attr:`PredictorRun.errors` (the last line of a message is
its summary). :func:`submission_from_predictor` writes placeholder dual grasps that cannot
succeed (both hands 5 m away from the object) for each failed object, as many as the most grasps
the predictor returned for any object (:func:`failed_placeholders`), so a failed object scores 0
and weighs as much as an answered one; it never leaves the denominator. The failures are listed in
the submission's metadata.
"""

from __future__ import annotations

import contextlib
import importlib
import importlib.util
import json
import math
import os
import resource
import shutil
import signal
import sys
import tempfile
import time
import traceback
import zipfile
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from multiprocessing import get_context
from multiprocessing.connection import Connection, wait
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from dataset_gen.errors import Dg16mError

if TYPE_CHECKING:
    from multiprocessing.process import BaseProcess

    from dg16m_env.evaluators.context import BenchmarkRef

#: Placeholder written for an object the predictor failed on: both hands, identity rotation,
#: 5 m from the object's centre of mass, where no grasp can touch it. (1, 2, 4, 4), m.
FAILED_PLACEHOLDER = np.tile(np.eye(4), (1, 2, 1, 1))
FAILED_PLACEHOLDER[0, 0, :3, 3] = (5.0, 0.0, 0.0)
FAILED_PLACEHOLDER[0, 1, :3, 3] = (5.0, 0.5, 0.0)
FAILED_PLACEHOLDER.setflags(write=False)


def failed_placeholders(answered: Mapping[str, np.ndarray]) -> np.ndarray:
    """The dual grasps written for an object the predictor failed on: :data:`FAILED_PLACEHOLDER`
    repeated as many times as the most grasps of any answered object (``answered``: object id
    -> (K, 2, 4, 4) poses), at least once. (K, 2, 4, 4), m."""
    k = max((len(p) for p in answered.values()), default=1)
    return np.repeat(FAILED_PLACEHOLDER, max(k, 1), axis=0)


_MAX_MESSAGE_BYTES = 1 << 20  # a JSON message from the child
_TRACEBACK_LINES = 5  # lines of traceback kept in an error message
_METADATA_ERROR_BYTES = 32_768  # the failed objects' messages in a submission's metadata
_STOP_GRACE_S = 1.0  # between SIGTERM and SIGKILL
_PR_SET_PDEATHSIG = 1
_MALFORMED = "it sent a malformed message"


class PredictorError(Dg16mError, ValueError):
    """A predictor that cannot run: a malformed target, an import that fails, bad arguments."""


class _OutputError(ValueError):
    """A predictor's return value that is not dual grasps (one object's error, no traceback)."""


class _StartError(Exception):
    """A child process that did not become ready (the message says why)."""


# --------------------------------------------------------------------------------------------
# The target


def _parse_target(target: Any) -> tuple[str, str, bool]:
    """Split ``target`` into (module or file, attribute path, is a file).

    Raises:
        PredictorError: not ``"package.module:callable"`` or ``"path/to/file.py:callable"``.
    """
    expected = "expected 'package.module:callable' or 'path/to/file.py:callable'"
    if not isinstance(target, str):
        raise PredictorError(f"target: {expected}, found {type(target).__name__}")
    module, sep, attribute = target.rpartition(":")
    if not sep or not module or not attribute:
        raise PredictorError(f"target: {expected}, found {target!r}")
    if not all(part.isidentifier() for part in attribute.split(".")):
        raise PredictorError(f"target: {expected}, found the attribute {attribute!r}")
    is_file = module.endswith(".py")
    if not is_file and not all(part.isidentifier() for part in module.split(".")):
        raise PredictorError(f"target: {expected}, found the module {module!r}")
    return module, attribute, is_file


def load_target(target: str, path: Sequence[str] = ()) -> Any:
    """Import ``target`` (``"package.module:attr"`` or ``"path/to/file.py:attr"``) in this process.

    ``path`` entries go to the front of ``sys.path`` first; a file target's folder too (as
    ``python file.py`` does), and the file is imported as the module ``dg16m_target_<stem>``. A
    dotted ``attr`` is followed attribute by attribute. Use it for your own, trusted code
    (:func:`run_predictor` calls it in the child process).

    Raises:
        PredictorError: a malformed target, a module or file not found, a missing attribute.
        Exception: whatever the module raises while it is imported.
    """
    module_name, attribute, is_file = _parse_target(target)
    for entry in reversed([str(p) for p in path]):
        if entry not in sys.path:
            sys.path.insert(0, entry)
    if is_file:
        file = Path(module_name).resolve()
        if not file.is_file():
            raise PredictorError(f"target {target!r}: expected a Python file at {file}, found none")
        if str(file.parent) not in sys.path:
            sys.path.insert(0, str(file.parent))
        name = "dg16m_target_" + "".join(c if c.isalnum() else "_" for c in file.stem)
        module_spec = importlib.util.spec_from_file_location(name, file)
        if module_spec is None or module_spec.loader is None:
            raise PredictorError(f"target {target!r}: expected an importable file, found {file}")
        module = importlib.util.module_from_spec(module_spec)
        sys.modules[name] = module
        try:
            module_spec.loader.exec_module(module)
        except BaseException:
            sys.modules.pop(name, None)
            raise
    else:
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            # The target itself (or a package above it) is missing: say so plainly. A module
            # missing deeper down (the target's own imports) keeps its traceback.
            parts = module_name.split(".")
            if exc.name in {".".join(parts[: k + 1]) for k in range(len(parts))}:
                raise PredictorError(
                    f"target {target!r}: expected an importable module {module_name!r}, found "
                    f"no module named {exc.name!r} (sys.path: add its folder with `path`)"
                ) from None
            raise
    value: Any = module
    for k, part in enumerate(attribute.split(".")):
        if not hasattr(value, part):
            owner = module_name if k == 0 else ".".join(attribute.split(".")[:k])
            raise PredictorError(
                f"target {target!r}: expected {owner!r} to have an attribute {part!r}, found none"
            )
        value = getattr(value, part)
    return value


@dataclass(frozen=True)
class PredictorSpec:
    """What to run and within which limits.

    Attributes:
        target: ``"package.module:callable"`` or ``"path/to/file.py:callable"`` (a file path is
            relative to the current folder).
        time_limit_s: seconds each call may take (wall clock, > 0).
        memory_limit_mb: address-space limit of the child process (MiB, ``RLIMIT_AS``; counts
            the interpreter and numpy too; 0 = no limit, e.g. for CUDA).
        startup_time_limit_s: seconds for the import; what it leaves over extends the first
            call of each child process (> 0).
        path: folders put in front of the child's ``sys.path``.

    Raises:
        PredictorError: a malformed target or limit.
    """

    target: str
    time_limit_s: float = 60.0
    memory_limit_mb: int = 4096
    startup_time_limit_s: float = 120.0
    path: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        _parse_target(self.target)
        for name in ("time_limit_s", "startup_time_limit_s"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise PredictorError(f"{name}: expected seconds > 0, found {value!r}")
            if not (math.isfinite(value) and value > 0):
                raise PredictorError(f"{name}: expected seconds > 0, found {value!r}")
        limit = self.memory_limit_mb
        if isinstance(limit, bool) or not isinstance(limit, (int, np.integer)) or limit < 0:
            raise PredictorError(
                f"memory_limit_mb: expected an integer >= 0 (MiB; 0 = no limit), found {limit!r}"
            )
        if isinstance(self.path, (str, bytes)) or not all(
            isinstance(p, (str, os.PathLike)) for p in self.path
        ):
            raise PredictorError(f"path: expected a sequence of folders, found {self.path!r}")
        object.__setattr__(self, "memory_limit_mb", int(limit))
        object.__setattr__(self, "path", tuple(str(p) for p in self.path))


# --------------------------------------------------------------------------------------------
# Dual grasps: conversion (child) and validation (both sides)


def _as_array(value: Any, name: str) -> np.ndarray:
    """``value`` as a numpy array (torch tensors: detached and moved to the CPU first)."""
    if hasattr(value, "detach") and hasattr(value, "cpu"):  # torch.Tensor without importing it
        value = value.detach().cpu()
    try:
        return np.asarray(value)
    except Exception as exc:
        raise _OutputError(
            f"{name}: expected an array, found {type(value).__name__} ({exc})"
        ) from None


def _grasp_arrays(value: Any) -> tuple[np.ndarray, np.ndarray | None]:
    """The (poses, scores) of a predictor's return value (array, tuple or dict), unchecked."""
    if isinstance(value, tuple):
        if len(value) != 2:
            raise _OutputError(
                f"expected a (poses, scores) tuple of 2 items, found a tuple of {len(value)}"
            )
        return _as_array(value[0], "poses"), _as_array(value[1], "scores")
    if isinstance(value, Mapping):
        keys = set(value)
        if "poses" not in keys or keys - {"poses", "scores"}:
            raise _OutputError(
                "expected a dict with the keys 'poses' and optionally 'scores', found "
                f"{sorted(map(str, keys))}"
            )
        scores = value.get("scores")
        return _as_array(value["poses"], "poses"), (
            None if scores is None else _as_array(scores, "scores")
        )
    if isinstance(value, np.ndarray) or hasattr(value, "__array__"):
        return _as_array(value, "poses"), None
    raise _OutputError(
        "expected an array (K, 2, 4, 4), a (poses, scores) tuple or a dict, found "
        f"{type(value).__name__}"
    )


def _check_grasps(
    poses: np.ndarray, scores: np.ndarray | None, max_grasps: int
) -> tuple[np.ndarray, np.ndarray | None]:
    """Validate the structure of dual grasps (dtype, shape, K, finite); return them as float64.

    The child checks this much before writing its result; the parent checks it again, and then
    :func:`_check_transforms`.

    Args:
        poses: (K, 2, 4, 4) float or integer hand poses (m).
        scores: (K,) float or integer, or None.
        max_grasps: largest K allowed.

    Raises:
        _OutputError: a dtype, shape, K or non-finite value (the message is the object's error).
    """
    for name, array in (("poses", poses), ("scores", scores)):
        if array is not None and array.dtype.kind not in "iuf":
            raise _OutputError(
                f"{name}: expected a float or integer array, found dtype {array.dtype}"
            )
    if poses.ndim != 4 or poses.shape[1:] != (2, 4, 4):
        raise _OutputError(f"poses: expected shape (K, 2, 4, 4), found {poses.shape}")
    k = poses.shape[0]
    if not 1 <= k <= max_grasps:
        raise _OutputError(f"poses: expected 1 to {max_grasps} dual grasps, found {k}")
    poses = poses.astype(np.float64)
    bad = int(np.count_nonzero(~np.isfinite(poses)))
    if bad:
        raise _OutputError(f"poses: expected finite values, found {bad} NaN or inf entries")
    if scores is None:
        return poses, None
    if scores.shape != (k,):
        raise _OutputError(f"scores: expected shape ({k},), found {scores.shape}")
    scores = scores.astype(np.float64)
    bad = int(np.count_nonzero(~np.isfinite(scores)))
    if bad:
        raise _OutputError(f"scores: expected finite values, found {bad} NaN or inf entries")
    return poses, scores


def _check_transforms(poses: np.ndarray) -> None:
    """Check that (K, 2, 4, 4) finite poses are what a submission accepts
    (:func:`dg16m_env.submission.hand_pose_faults`), so a run's grasps always make a valid file.

    Raises:
        _OutputError: a hand pose that is not rigid or too far away (m).
    """
    from dg16m_env.submission import hand_pose_faults

    for faulty, message in hand_pose_faults(poses):
        if faulty.any():
            grasp, hand = np.argwhere(faulty)[0]
            raise _OutputError(
                f"poses: {message} in {int(faulty.sum())} hand poses (first: grasp {grasp}, "
                f"hand {hand})"
            )


def _read_result(file: Path, max_grasps: int) -> tuple[np.ndarray, np.ndarray | None]:
    """Load and validate a child's ``.npz`` (no pickle; sizes checked before reading).

    Raises:
        _OutputError: a missing or malformed file, or invalid grasps.
    """
    limits = {"poses.npy": max_grasps * 32 * 8 + 4096, "scores.npy": max_grasps * 8 + 4096}
    try:
        with zipfile.ZipFile(file) as archive:
            sizes = {info.filename: info.file_size for info in archive.infolist()}
        if "poses.npy" not in sizes or set(sizes) - set(limits):
            raise _OutputError(
                f"result file: expected poses.npy and optionally scores.npy, found {sorted(sizes)}"
            )
        for name, size in sizes.items():
            if size > limits[name]:
                raise _OutputError(
                    f"result file: expected {name} of at most {limits[name]} bytes, found {size}"
                )
        with np.load(file, allow_pickle=False) as data:
            poses = data["poses"]
            scores = data["scores"] if "scores.npy" in sizes else None
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        if isinstance(exc, _OutputError):
            raise
        raise _OutputError(f"result file: expected a readable .npz, found {exc}") from None
    poses, scores = _check_grasps(poses, scores, max_grasps)
    _check_transforms(poses)
    return poses, scores


# --------------------------------------------------------------------------------------------
# The child process


def _send(conn: Connection, message: dict[str, Any]) -> None:
    """Send a JSON message to the parent (never a pickle)."""
    conn.send_bytes(json.dumps(message).encode())


def _describe(exc: BaseException, memory_limit_mb: int = 0) -> str:
    """``exc`` as the last lines of its traceback, then ``Type: message`` (the summary line)."""
    lines: list[str] = []
    tb = exc.__traceback__
    if tb is not None and tb.tb_next is not None:  # the first frame is ours
        tb = tb.tb_next
    if tb is not None:
        lines = "".join(traceback.format_tb(tb)).rstrip().splitlines()[-_TRACEBACK_LINES:]
    text = str(exc).replace("\n", " ")
    summary = f"{type(exc).__name__}: {text}" if text else type(exc).__name__
    if isinstance(exc, MemoryError) and memory_limit_mb:
        summary += f" (out of memory: the predictor may use {memory_limit_mb} MB of address space)"
    return "\n".join([*lines, summary])


def _address_space_bytes() -> int:
    """The virtual address space of this process (bytes; 0 when unknown)."""
    with contextlib.suppress(OSError, ValueError, IndexError):
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmSize:"):
                return int(line.split()[1]) * 1024
    return 0


def _set_limits(memory_limit_mb: int) -> None:
    """Core dumps off, the address-space limit on, own process group, die with the parent."""
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    with contextlib.suppress(OSError):
        os.setpgid(0, 0)
    with contextlib.suppress(Exception):  # best effort: Linux only
        import ctypes

        ctypes.CDLL(None).prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL))
    if not memory_limit_mb:
        return
    limit = memory_limit_mb * 1024 * 1024
    _, hard = resource.getrlimit(resource.RLIMIT_AS)
    if hard != resource.RLIM_INFINITY:
        limit = min(limit, hard)
    used = _address_space_bytes()
    if used >= limit:
        raise PredictorError(
            f"memory_limit_mb: expected more than the {used / 2**20:.0f} MB of address space the "
            f"predictor's process uses before importing the target, found {memory_limit_mb}"
        )
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))


def _child_main(
    conn: Connection,
    target: str,
    path: tuple[str, ...],
    memory_limit_mb: int,
    max_grasps: int,
    workdir: str,
) -> None:
    """The child: set limits, import the target, then answer ``(index, observation)`` messages
    until ``None`` or the end of the pipe (results in ``workdir/<index>.npz``)."""
    try:
        _set_limits(memory_limit_mb)
        predict = load_target(target, path)
        if not callable(predict):
            raise PredictorError(
                f"target {target!r}: expected a callable, found {type(predict).__name__}"
            )
    except BaseException as exc:  # report anything that stops the import, SystemExit included
        message = str(exc) if isinstance(exc, PredictorError) else _describe(exc, memory_limit_mb)
        _send(conn, {"kind": "startup_error", "message": message})
        return
    _send(conn, {"kind": "ready"})
    while True:
        try:
            request = conn.recv()
        except (EOFError, OSError):
            return
        if request is None:
            return
        index, observation = request
        try:
            value = predict(observation)
        except (Exception, SystemExit) as exc:
            _send(
                conn, {"kind": "error", "index": index, "message": _describe(exc, memory_limit_mb)}
            )
            continue
        try:
            poses, scores = _check_grasps(*_grasp_arrays(value), max_grasps)
            arrays = {"poses": poses} if scores is None else {"poses": poses, "scores": scores}
            np.savez(Path(workdir) / f"{index}.npz", allow_pickle=False, **arrays)
        except _OutputError as exc:
            _send(conn, {"kind": "error", "index": index, "message": str(exc)})
            continue
        except (Exception, SystemExit) as exc:
            _send(
                conn, {"kind": "error", "index": index, "message": _describe(exc, memory_limit_mb)}
            )
            continue
        _send(conn, {"kind": "result", "index": index})


# --------------------------------------------------------------------------------------------
# The parent side


def _exit_description(exitcode: int | None) -> str:
    """``exit code N`` or ``signal NAME`` of a finished process."""
    if exitcode is None:
        return "exit status unknown"
    if exitcode < 0:
        try:
            return f"signal {signal.Signals(-exitcode).name}"
        except ValueError:
            return f"signal {-exitcode}"
    return f"exit code {exitcode}"


class _Worker:
    """One child process at a time: start, ask, stop (see the module docstring)."""

    def __init__(self, spec: PredictorSpec, max_grasps: int, workdir: Path) -> None:
        self.spec = spec
        self.max_grasps = max_grasps
        self.workdir = workdir
        self.process: BaseProcess | None = None
        self.conn: Connection | None = None
        self.startup_s = 0.0
        self.calls = 0

    @property
    def alive(self) -> bool:
        return self.process is not None

    def start(self) -> None:
        """Start a child and wait until it imported the target.

        Raises:
            _StartError: an import error, a timeout or a death during startup.
        """
        ctx = get_context("spawn")
        parent_conn, child_conn = ctx.Pipe(duplex=True)
        args = (
            child_conn,
            self.spec.target,
            self.spec.path,
            self.spec.memory_limit_mb,
            self.max_grasps,
            str(self.workdir),
        )
        # Not a daemon: a daemonic process may not start processes (data loaders, pools).
        process = ctx.Process(target=_child_main, args=args, name="dg16m-predictor", daemon=False)
        started = time.monotonic()
        process.start()
        child_conn.close()  # so that the child's death reads as the end of the pipe
        self.process, self.conn, self.calls = process, parent_conn, 0
        limit = self.spec.startup_time_limit_s
        message = self._receive(limit)
        self.startup_s = time.monotonic() - started
        if isinstance(message, dict) and message.get("kind") == "ready":
            return
        self.stop()
        if isinstance(message, dict) and message.get("kind") == "startup_error":
            raise _StartError(str(message.get("message", "")))
        if message == "timeout":
            raise _StartError(f"the import timed out after {limit:.3g} s")
        raise _StartError(f"the predictor process died during startup ({message})")

    def _receive(self, limit: float) -> dict[str, Any] | str:
        """The child's next message, or ``"timeout"``, or how it died (a str)."""
        assert self.process is not None
        assert self.conn is not None
        deadline = time.monotonic() + limit
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return "timeout"
            ready = wait([self.conn, self.process.sentinel], timeout=remaining)
            if self.conn in ready or self.conn.poll(0):
                try:
                    raw = self.conn.recv_bytes(_MAX_MESSAGE_BYTES)
                except (EOFError, OSError):
                    return self._death()
                try:
                    message = json.loads(raw)
                except ValueError:
                    message = None
                if not isinstance(message, dict) or not isinstance(message.get("kind"), str):
                    return _MALFORMED
                return message
            if self.process.sentinel in ready:
                return self._death()

    def _death(self) -> str:
        """How the child ended (it closed the pipe or exited)."""
        assert self.process is not None
        self.process.join(_STOP_GRACE_S)
        if self.process.exitcode is None:
            return "it closed its connection"
        return _exit_description(self.process.exitcode)

    def ask(
        self, index: int, observation: Mapping[str, Any], limit: float
    ) -> tuple[np.ndarray, np.ndarray | None] | str:
        """Run one observation: its (poses, scores), or its error message (the child is stopped
        after a timeout, a death or a protocol error)."""
        assert self.conn is not None
        self.calls += 1
        try:
            self.conn.send((index, dict(observation)))
        except (BrokenPipeError, ConnectionResetError, EOFError):
            message: dict[str, Any] | str = self._death()
        else:
            message = self._receive(limit)
        if message == "timeout":
            self.stop()
            return f"timed out after {limit:.3g} s"
        if message == _MALFORMED or (
            isinstance(message, dict)
            and (message.get("index") != index or message["kind"] not in ("result", "error"))
        ):
            self.stop()
            return "the predictor process was stopped: it sent a malformed message"
        if isinstance(message, str):
            self.stop()
            return f"the predictor process died ({message})"
        if message["kind"] == "error":
            return str(message.get("message", ""))
        file = self.workdir / f"{index}.npz"
        try:
            return _read_result(file, self.max_grasps)
        except _OutputError as exc:
            return str(exc)
        finally:
            file.unlink(missing_ok=True)

    def close(self) -> None:
        """Ask the child to exit, then make sure it did."""
        if self.conn is not None and self.process is not None:
            with contextlib.suppress(OSError, ValueError):
                self.conn.send(None)
            self.process.join(_STOP_GRACE_S)
        self.stop()

    def stop(self) -> None:
        """Kill the child and its process group (SIGTERM, then SIGKILL) and reap it."""
        process, conn = self.process, self.conn
        self.process, self.conn = None, None
        if conn is not None:
            conn.close()
        if process is None:
            return
        for sig in (signal.SIGTERM, signal.SIGKILL):
            if process.exitcode is not None:
                break
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(process.pid, sig)  # the child leads its own group (see _set_limits)
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(process.pid, sig)  # in case it died before joining its group
            process.join(_STOP_GRACE_S if sig == signal.SIGTERM else None)
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(process.pid, signal.SIGKILL)  # anything it left in its group
        process.close()


@dataclass(eq=False)
class PredictorRun:
    """What a predictor produced, per object id, in the order the objects were run.

    Attributes:
        poses: object id -> (K, 2, 4, 4) float64 hand poses (m), for the objects that succeeded.
        scores: object id -> (K,) float64 scores, for those that returned scores.
        errors: object id -> error message (last line: the summary), for those that failed.
        seconds: object id -> wall seconds from sending the observation to the answer (s).
        target: the predictor's target.
        restarts: child processes started after a timeout or a death.
    """

    poses: dict[str, np.ndarray] = field(default_factory=dict)
    scores: dict[str, np.ndarray] = field(default_factory=dict)
    errors: dict[str, str] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)
    target: str = ""
    restarts: int = 0

    @property
    def object_ids(self) -> list[str]:
        """Every object run, in order."""
        return list(self.seconds)

    def summary(self) -> dict[str, Any]:
        """Counts, times (s) and every error (JSON-ready)."""
        seconds = list(self.seconds.values())
        return {
            "target": self.target,
            "objects": len(self.seconds),
            "succeeded": len(self.poses),
            "failed": len(self.errors),
            "restarts": self.restarts,
            "dual_grasps": int(sum(len(p) for p in self.poses.values())),
            "seconds_total": float(sum(seconds)),
            "seconds_max": float(max(seconds, default=0.0)),
            "errors": dict(self.errors),
        }

    def __repr__(self) -> str:  # arrays: count them
        return (
            f"PredictorRun({self.target!r}: {len(self.poses)} objects succeeded, "
            f"{len(self.errors)} failed, {self.restarts} restarts)"
        )


def _object_id(observation: Any, run: PredictorRun) -> str:
    """The observation's object id (a new, non-empty str)."""
    object_id = observation.get("object_id") if isinstance(observation, Mapping) else None
    if not isinstance(object_id, str) or not object_id:
        raise PredictorError(
            "observations: expected dicts with a non-empty str 'object_id', found "
            f"{type(observation).__name__} with object_id {object_id!r}"
        )
    if object_id in run.seconds:
        raise PredictorError(f"observations: expected unique object ids, found {object_id!r} twice")
    return object_id


def run_predictor(
    spec: PredictorSpec,
    observations: Iterable[Mapping[str, Any]],
    *,
    max_grasps: int = 100,
    progress: bool = False,
) -> PredictorRun:
    """Run ``spec.target`` on every observation in a child process (see the module docstring).

    Args:
        spec: the target and its limits.
        observations: observation dicts (:func:`dg16m_env.observation.object_observation`),
            consumed lazily, one at a time; each needs a unique str ``object_id``.
        max_grasps: dual grasps per object at most (K <= max_grasps).
        progress: show a progress bar (and each failure) on stderr.

    Returns:
        Per object: the validated grasps, or the error (timeouts, deaths, exceptions and invalid
        return values do not stop the run).

    Raises:
        PredictorError: the target cannot be imported or is not callable, the child cannot start
            (e.g. a memory limit under its baseline), a malformed observation, bad ``max_grasps``.
    """
    if not isinstance(spec, PredictorSpec):
        raise PredictorError(f"spec: expected a PredictorSpec, found {type(spec).__name__}")
    if isinstance(max_grasps, bool) or not isinstance(max_grasps, (int, np.integer)):
        raise PredictorError(f"max_grasps: expected an integer >= 1, found {max_grasps!r}")
    if max_grasps < 1:
        raise PredictorError(f"max_grasps: expected an integer >= 1, found {max_grasps}")
    max_grasps = int(max_grasps)
    run = PredictorRun(target=spec.target)
    workdir = Path(tempfile.mkdtemp(prefix="dg16m-predictor-"))  # private: mode 0700
    worker = _Worker(spec, max_grasps, workdir)
    bar = None
    try:
        try:
            worker.start()
        except _StartError as exc:
            raise PredictorError(f"predictor {spec.target!r} failed to start: {exc}") from None
        if progress:
            from tqdm import tqdm

            total = len(observations) if hasattr(observations, "__len__") else None
            bar = tqdm(total=total, unit="object", desc="predictor")
        broken: str | None = None  # why no child can run the rest
        for index, observation in enumerate(observations):
            object_id = _object_id(observation, run)
            started = time.perf_counter()
            outcome: tuple[np.ndarray, np.ndarray | None] | str
            if broken is None and not worker.alive:
                try:
                    worker.start()
                    run.restarts += 1
                except _StartError as exc:
                    reason = str(exc).splitlines()[-1] if str(exc) else "unknown"
                    broken = f"not run: the predictor could not be restarted: {reason}"
            if broken is not None:
                outcome = broken
            else:
                limit = spec.time_limit_s
                if worker.calls == 0:  # the first call may use what the import left over
                    limit += max(0.0, spec.startup_time_limit_s - worker.startup_s)
                outcome = worker.ask(index, observation, limit)
            run.seconds[object_id] = time.perf_counter() - started
            if isinstance(outcome, str):
                run.errors[object_id] = outcome
                if bar is not None:
                    bar.write(f"predictor: {object_id}: {outcome.splitlines()[-1]}")
            else:
                run.poses[object_id] = outcome[0]
                if outcome[1] is not None:
                    run.scores[object_id] = outcome[1]
            if bar is not None:  # one refresh per object (a log shows each update once)
                bar.set_postfix(failed=len(run.errors), refresh=False)
                bar.update(1)
        worker.close()
    finally:
        worker.stop()
        shutil.rmtree(workdir, ignore_errors=True)
        if bar is not None:
            bar.close()
    return run


# --------------------------------------------------------------------------------------------
# Submissions


class _Observations:
    """The benchmark's observations, built one at a time (sized, for the progress bar)."""

    def __init__(self, ref: BenchmarkRef, mesh_root: Path | None, n_points: int, seed: int) -> None:
        self.ref, self.mesh_root, self.n_points, self.seed = ref, mesh_root, n_points, seed

    def __len__(self) -> int:
        return len(self.ref.benchmark.objects)

    def __iter__(self) -> Iterator[dict[str, Any]]:
        from dg16m_env.observation import object_observation

        for obj in self.ref.benchmark.objects:
            grasp_object = obj.load(self.mesh_root)
            yield object_observation(grasp_object, n_points=self.n_points, seed=self.seed)


def _metadata_errors(
    errors: Mapping[str, str], budget: int = _METADATA_ERROR_BYTES
) -> dict[str, str]:
    """Each error's summary line, shortened so that all of them fit in about ``budget`` bytes."""
    if not errors:
        return {}
    cap = max(40, min(200, budget // len(errors) - max(len(i) for i in errors) - 8))
    out = {}
    for object_id, message in errors.items():
        summary = message.splitlines()[-1] if message else ""
        out[object_id] = summary if len(summary) <= cap else summary[: cap - 3] + "..."
    return out


def submission_from_predictor(
    spec: PredictorSpec,
    out_path: str | os.PathLike[str],
    *,
    benchmark: str | os.PathLike[str] | BenchmarkRef | None = None,
    mesh_root: str | os.PathLike[str] | None = None,
    n_points: int = 2048,
    seed: int = 0,
    max_grasps: int = 100,
    progress: bool = True,
) -> tuple[Path, PredictorRun]:
    """Run a predictor on every benchmark object and write its submission file atomically.

    Each object's observation (:func:`dg16m_env.observation.object_observation` with
    ``n_points`` and ``seed``) is built just before it is needed. An object the predictor failed
    on gets :func:`failed_placeholders` (as many copies of :data:`FAILED_PLACEHOLDER`, a dual
    grasp 5 m away that cannot succeed, as the most grasps the predictor returned for any
    object; no score): it scores 0, stays in the denominator and weighs as much there as an
    object the predictor answered, so failing on hard objects cannot raise a rate. The metadata
    records ``predictor`` (the target), ``failed_objects`` (id -> the error's summary line,
    shortened), ``failed_grasps_per_object``, ``n_points``, ``seed``, ``max_grasps`` and the
    limits.

    Args:
        spec: the predictor and its limits.
        out_path: the submission file (HDF5) to write.
        benchmark: a benchmark file, a loaded :class:`BenchmarkRef`, or None for the embedded one.
        mesh_root: folder of a mesh benchmark's meshes (default: the ref's).
        n_points: points per observation.
        seed: seed of the observations' point clouds.
        max_grasps: dual grasps per object at most.
        progress: show a progress bar on stderr.

    Returns:
        The file written and the run (every error in full).

    Raises:
        PredictorError: see :func:`run_predictor`.
        BenchmarkError: an unreadable benchmark, a mesh object without ``mesh_root``.
        ObservationError: a bad ``n_points`` or ``seed``.
    """
    from dataset_gen.checks import check_integer
    from dg16m_env.evaluators.context import load_benchmark_ref
    from dg16m_env.observation import ObservationError
    from dg16m_env.submission import EMBEDDED, write_submission

    check_integer("n_points", n_points, minimum=1, error=ObservationError)
    check_integer("seed", seed, minimum=0, error=ObservationError)
    ref = load_benchmark_ref(benchmark, mesh_root)
    root = Path(mesh_root) if mesh_root is not None else ref.mesh_root
    run = run_predictor(
        spec,
        _Observations(ref, root, int(n_points), int(seed)),
        max_grasps=max_grasps,
        progress=progress,
    )
    failed = failed_placeholders(run.poses)
    poses = {i: run.poses.get(i, failed) for i in ref.object_ids}
    metadata = {
        "predictor": spec.target,
        "failed_objects": _metadata_errors(run.errors),
        "failed_grasps_per_object": len(failed),
        "n_points": int(n_points),
        "seed": int(seed),
        "max_grasps": int(max_grasps),
        "time_limit_s": spec.time_limit_s,
        "memory_limit_mb": spec.memory_limit_mb,
    }
    path = write_submission(
        out_path,
        poses,
        scores=run.scores,
        benchmark=EMBEDDED if ref.embedded else ref.sha256,
        metadata=metadata,
    )
    return path, run
