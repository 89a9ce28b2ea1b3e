"""Keep a predictor's process from reading the benchmark: Linux Landlock, from the child itself.

A cloud-track predictor (``dg16m evaluate --predictor X --track cloud``) must not see the mesh.
The harness never sends it, and :func:`restrict_reading` makes the child process unable to read
the files that hold it: the benchmark file, the mesh folder (``--mesh-root``) and the package's
data folder of shipped benchmarks. It runs in the child before the target is imported.

Landlock (Linux 5.13 and later; syscalls 444 ``landlock_create_ruleset``, 445
``landlock_add_rule``, 446 ``landlock_restrict_self``, after ``prctl(PR_SET_NO_NEW_PRIVS)``) is an
allow list of file hierarchies, inherited by every process the child starts and irrevocable. The
ruleset handles two rights, reading a file and listing a folder; everything else (writing,
executing, the network) is untouched. It grants, walking from ``/``:

* listing folders everywhere (a folder on the way to a forbidden path must stay listable, or
  Python cannot import the modules beside it; the names inside a forbidden folder can therefore
  be listed, never read);
* reading (and listing) each entry of a folder on the way to a forbidden path that is neither
  forbidden nor itself on the way to one (a symlink counts by its target); the walk goes on
  inside the folders on the way.

So every file can be read except those at or beneath a forbidden path. Landlock also keeps the
process from tracing, or reading the memory of (``/proc/<pid>/mem``), any process outside its
domain: the harness that holds the mesh included. What the walk cannot see
is not covered: the same file reached through another mount (a bind mount) stays readable.
Where Landlock is missing (another OS, an older kernel, a container that blocks the syscalls),
:func:`restrict_reading` changes nothing and says so (``"none"``): the run goes on and its
submission records ``"sandbox": "none"``.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import sys
from collections.abc import Iterable

_CREATE_RULESET, _ADD_RULE, _RESTRICT_SELF = 444, 445, 446  # every Linux architecture
_CREATE_RULESET_VERSION = 1
_RULE_PATH_BENEATH = 1
_PR_SET_NO_NEW_PRIVS = 38
_O_PATH = getattr(os, "O_PATH", 0o10000000)

READ_FILE = 1 << 2
"""``LANDLOCK_ACCESS_FS_READ_FILE``."""
READ_DIR = 1 << 3
"""``LANDLOCK_ACCESS_FS_READ_DIR``."""

NO_SANDBOX = "none"
"""What :func:`restrict_reading` returns where Landlock is unavailable."""


class _RulesetAttr(ctypes.Structure):
    _fields_ = [("handled_access_fs", ctypes.c_uint64)]


class _PathBeneathAttr(ctypes.Structure):
    _pack_ = 1
    _fields_ = [("allowed_access", ctypes.c_uint64), ("parent_fd", ctypes.c_int32)]


def _libc() -> ctypes.CDLL | None:
    """The C library with ``errno`` (None off Linux)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL(None, use_errno=True)
    except OSError:
        return None


def landlock_abi() -> int:
    """The kernel's Landlock ABI version (0: unavailable here)."""
    libc = _libc()
    if libc is None:
        return 0
    version = libc.syscall(
        ctypes.c_long(_CREATE_RULESET), None, ctypes.c_size_t(0), ctypes.c_uint32(1)
    )
    return max(int(version), 0)


def _under(path: str, roots: Iterable[str]) -> bool:
    """Whether ``path`` is one of ``roots`` or lies beneath one (real paths)."""
    return any(path == r or path.startswith(r.rstrip("/") + "/") for r in roots)


def allowed_entries(forbidden: Iterable[str | os.PathLike[str]]) -> list[tuple[str, bool]]:
    """The paths to grant reading (see the module docstring), each with whether it is a folder.

    Args:
        forbidden: files or folders that must not be read (made absolute and real; missing
            ones are ignored).
    """
    blocked = {os.path.realpath(os.fspath(p)) for p in forbidden}
    blocked = {p for p in blocked if os.path.lexists(p)}
    ancestors: set[str] = set()
    for path in blocked:
        parent = os.path.dirname(path)
        while True:
            ancestors.add(parent)
            if parent == os.path.dirname(parent):
                break
            parent = os.path.dirname(parent)
    out: list[tuple[str, bool]] = []
    stack = sorted(ancestors & {"/"}) if blocked else []
    while stack:
        folder = stack.pop()
        try:
            entries = sorted(os.scandir(folder), key=lambda e: e.name)
        except OSError:
            continue
        for entry in entries:
            path = entry.path
            real = os.path.realpath(path)
            if path in ancestors and not entry.is_symlink():
                stack.append(path)
                continue
            if _under(real, blocked) or real in ancestors or _under(path, blocked):
                continue  # a symlink to (or above) a forbidden path: the walk covers its target
            with contextlib.suppress(OSError):
                out.append((path, entry.is_dir()))
    return out


def restrict_reading(forbidden: Iterable[str | os.PathLike[str]]) -> str:
    """Make this process (and every process it starts) unable to read ``forbidden`` paths.

    Returns:
        ``"landlock-abi-N"`` once restricted, :data:`NO_SANDBOX` where Landlock is unavailable
        (nothing changed). An entry the kernel refuses as a rule (e.g. a file this user may
        not open) is left out, so it cannot be read either.

    Raises:
        OSError: Landlock is available but a step failed after the rules were made.
    """
    abi = landlock_abi()
    libc = _libc()
    if abi < 1 or libc is None:
        return NO_SANDBOX
    attr = _RulesetAttr(READ_FILE | READ_DIR)
    ruleset = libc.syscall(
        ctypes.c_long(_CREATE_RULESET),
        ctypes.byref(attr),
        ctypes.c_size_t(ctypes.sizeof(attr)),
        ctypes.c_uint32(0),
    )
    if ruleset < 0:
        return NO_SANDBOX
    try:
        rules = [("/", True, READ_DIR)]
        rules += [
            (p, d, READ_FILE | READ_DIR if d else READ_FILE) for p, d in allowed_entries(forbidden)
        ]
        for path, _, access in rules:
            try:
                fd = os.open(path, _O_PATH | os.O_CLOEXEC)
            except OSError:
                continue
            try:
                rule = _PathBeneathAttr(access, fd)
                libc.syscall(
                    ctypes.c_long(_ADD_RULE),
                    ctypes.c_int(ruleset),
                    ctypes.c_int(_RULE_PATH_BENEATH),
                    ctypes.byref(rule),
                    ctypes.c_uint32(0),
                )
            finally:
                os.close(fd)
        if libc.prctl(_PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0) != 0:
            raise OSError(ctypes.get_errno(), "prctl(PR_SET_NO_NEW_PRIVS) failed")
        if libc.syscall(ctypes.c_long(_RESTRICT_SELF), ctypes.c_int(ruleset), ctypes.c_uint32(0)):
            raise OSError(ctypes.get_errno(), "landlock_restrict_self failed")
    finally:
        os.close(ruleset)
    return f"landlock-abi-{abi}"


__all__ = [
    "NO_SANDBOX",
    "READ_DIR",
    "READ_FILE",
    "allowed_entries",
    "landlock_abi",
    "restrict_reading",
]
