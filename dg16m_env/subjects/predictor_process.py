"""The child process that runs a predictor given as code (see :mod:`dg16m_env.subjects.predictor`
for the isolation model and the observation / return contract): loading the target
(:func:`load_target`, :class:`PredictorSpec`), the child's limits and main loop, the messages
between it and this process, the checks of every array it returns, and the supervisor that
restarts it after a timeout or a crash.
"""

from __future__ import annotations

import contextlib
import importlib
import importlib.util
import json
import math
import multiprocessing
import os
import resource
import signal
import sys
import time
import traceback
import zipfile
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from multiprocessing import get_context
from multiprocessing.connection import Connection, wait
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from dg16m_core.errors import Dg16mError

if TYPE_CHECKING:
    from multiprocessing.process import BaseProcess


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


class _Stopped(BaseException):
    """SIGTERM in the child (this process stops it): unwind and end normally, so that
    multiprocessing's finalizers run (a semaphore made in the child, e.g. tqdm's lock, is
    unlinked and unregistered from the resource tracker it shares with this process, which would
    otherwise report it as leaked when this process exits)."""


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
    (:func:`~dg16m_env.subjects.predictor.run_predictor` calls it in the child process).

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
    (:func:`dg16m_env.subjects.submission.hand_pose_faults`), so a run's grasps always make a valid file.

    Raises:
        _OutputError: a hand pose that is not rigid or too far away (m).
    """
    from dg16m_env.subjects.submission import hand_pose_faults

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


def _on_sigterm(owner: int) -> Callable[[int, Any], None]:
    """The child's SIGTERM handler: raise :class:`_Stopped` once in the child itself; a process
    the predictor forked (it inherits the handler) gets the default action, as before."""

    def handler(signum: int, frame: Any) -> None:
        if os.getpid() != owner:
            signal.signal(signal.SIGTERM, signal.SIG_DFL)
            os.kill(os.getpid(), signal.SIGTERM)
            return
        signal.signal(signal.SIGTERM, signal.SIG_IGN)  # a second one must not cut the unwinding
        raise _Stopped

    return handler


@dataclass(frozen=True)
class _ChildJob:
    """What a child runs: the target and its import path, its memory limit, the most dual grasps
    an answer may hold, the folder of its results, and the paths it must not read (None: no
    sandbox; :func:`dg16m_env.subjects.sandbox.restrict_reading`)."""

    target: str
    path: tuple[str, ...]
    memory_limit_mb: int
    max_grasps: int
    workdir: str
    forbidden: tuple[str, ...] | None = None


def _child_main(conn: Connection, job: _ChildJob, start_method: str | None = None) -> None:
    """The child: set limits, import the target, then answer ``(index, observation)`` messages
    until ``None`` or the end of the pipe (results in ``workdir/<index>.npz``); SIGTERM ends it
    normally (:class:`_Stopped`).

    ``start_method`` is the parent's default multiprocessing start method: the bootstrap of a
    "spawn" child makes "spawn" its default, so without it the predictor's own locks and pools
    (tqdm makes a lock for every progress bar) would use named semaphores registered with the
    parent's resource tracker, and a child stopped mid-call left them "leaked".
    """
    signal.signal(signal.SIGTERM, _on_sigterm(os.getpid()))
    if start_method is not None:
        multiprocessing.set_start_method(start_method, force=True)
    with contextlib.suppress(_Stopped):
        _serve(conn, job)


def _serve(conn: Connection, job: _ChildJob) -> None:
    """:func:`_child_main`'s work: the import, then the calls."""
    target, memory_limit_mb, max_grasps = job.target, job.memory_limit_mb, job.max_grasps
    sandbox = None
    try:
        _set_limits(memory_limit_mb)
        if job.forbidden is not None:  # before the import: the target's code runs restricted
            from dg16m_env.subjects.sandbox import restrict_reading

            sandbox = restrict_reading(job.forbidden)
        predict = load_target(target, job.path)
        if not callable(predict):
            raise PredictorError(
                f"target {target!r}: expected a callable, found {type(predict).__name__}"
            )
    except _Stopped:
        raise
    except BaseException as exc:  # report anything that stops the import, SystemExit included
        message = str(exc) if isinstance(exc, PredictorError) else _describe(exc, memory_limit_mb)
        _send(conn, {"kind": "startup_error", "message": message})
        return
    _send(conn, {"kind": "ready", "sandbox": sandbox})
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
            np.savez(Path(job.workdir) / f"{index}.npz", allow_pickle=False, **arrays)
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

    def __init__(
        self,
        spec: PredictorSpec,
        max_grasps: int,
        workdir: Path,
        forbidden: tuple[str, ...] | None = None,
    ) -> None:
        self.spec = spec
        self.forbidden = forbidden
        self.sandbox: str | None = None  # what the last child reported (None: not asked)
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
        job = _ChildJob(
            self.spec.target,
            self.spec.path,
            self.spec.memory_limit_mb,
            self.max_grasps,
            str(self.workdir),
            self.forbidden,
        )
        # the parent's default start method: the child's own default becomes "spawn"
        args = (child_conn, job, multiprocessing.get_start_method())
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
            sandbox = message.get("sandbox")
            self.sandbox = sandbox if isinstance(sandbox, str) else None
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
