"""The board's files: submission files stored by content hash, and uploads being received.

* ``<db stem>.files/<aa>/<sha256>.h5``: a submission file, written atomically (a temporary file
  in the same folder, fsynced, then hard-linked into place, so a stored file is never
  overwritten and never seen half-written);
* ``<db stem>.uploads/upload-*.h5``: an upload while its body streams in and is validated
  (the service removes it when the request ends).

A process that writes or is about to reference a file holds a shared ``flock`` on it until it
is done (:meth:`FileStore.kept`, :meth:`FileStore.upload`). A lock dies with its process, so
:meth:`FileStore.remove_orphans` (run when the service starts) can tell a file left by a killed
process (it takes the file's exclusive lock at once) from one in use (it cannot), and removes
only the former: interrupted uploads, temporary copies, and stored files no submission refers
to.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import re
import shutil
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import BinaryIO

from .query_checks import BoardError

_SHA = re.compile(r"^[0-9a-f]{64}$")
UPLOAD_PREFIX = "upload-"
"""Name prefix of the temporary files of uploads (``upload-*.h5``)."""
_TMP_MARK = ".tmp-"


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _same_file(handle: BinaryIO, path: Path) -> bool:
    """Whether ``path`` still names the open file (it was not removed or replaced)."""
    try:
        named = os.stat(path)
    except FileNotFoundError:
        return False
    held = os.fstat(handle.fileno())
    return (named.st_dev, named.st_ino) == (held.st_dev, held.st_ino)


def _fsync_directory(directory: Path) -> None:
    fd = os.open(directory, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _try_exclusive(path: Path) -> BinaryIO | None:
    """``path`` opened with its exclusive lock taken, or None when another process holds a lock
    on it (it is in use) or it is gone."""
    try:
        handle = open(path, "rb")  # noqa: SIM115  (closed by the caller, holding the lock)
    except FileNotFoundError:
        return None
    try:
        fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        handle.close()
        return None
    return handle


class FileStore:
    """The submission files of one board and its uploads folder.

    Args:
        files: the content store (``<db stem>.files``).
        uploads: the uploads folder (``<db stem>.uploads``).
    """

    def __init__(self, files: Path, uploads: Path) -> None:
        self.files, self.uploads = files, uploads

    def path(self, sha256: str) -> Path:
        """Where the submission file with this content hash is stored."""
        if not isinstance(sha256, str) or not _SHA.match(sha256):
            raise BoardError(f"sha256: expected 64 hex digits, found {sha256!r}")
        return self.files / sha256[:2] / f"{sha256}.h5"

    @contextlib.contextmanager
    def kept(self, source: str | os.PathLike[str], sha256: str, size: int) -> Iterator[Path]:
        """The file with hash ``sha256`` in the store, held until the block ends.

        The file is copied from ``source`` unless the store has it already (a stored file of
        another size is replaced). The caller vouches that ``source`` has that hash (it hashed
        it while validating it), so nothing is hashed here; it records the submission inside
        the block, so :meth:`remove_orphans` never takes the file away in between.
        """
        destination = self.path(sha256)
        destination.parent.mkdir(parents=True, exist_ok=True)
        for _ in range(8):  # each turn loses only to a concurrent writer or cleaner
            handle = self._held(destination)
            if handle is not None and os.fstat(handle.fileno()).st_size == size:
                with handle:
                    yield destination
                return
            replace = handle is not None
            if handle is not None:
                handle.close()
            handle = self._copy(source, destination, replace=replace)
            if handle is not None:
                with handle:
                    yield destination
                return
        raise BoardError(
            f"{destination}: expected to store the file, found it changed by another process "
            "at every try"
        )

    def _held(self, path: Path) -> BinaryIO | None:
        """``path`` opened with a shared lock, or None when it is not there."""
        try:
            handle = open(path, "rb")  # noqa: SIM115  (returned open, holding the lock)
        except FileNotFoundError:
            return None
        fcntl.flock(handle.fileno(), fcntl.LOCK_SH)  # waits while a cleaner holds it
        if _same_file(handle, path):
            return handle
        handle.close()  # removed by the cleaner meanwhile
        return None

    def _copy(
        self, source: str | os.PathLike[str], path: Path, *, replace: bool
    ) -> BinaryIO | None:
        """Copy ``source`` to ``path`` atomically; the new file open with a shared lock, or
        None when another process stored one first (then use that)."""
        fd, tmp_name = tempfile.mkstemp(
            prefix=f".{path.name}{_TMP_MARK}", suffix=".h5", dir=path.parent
        )
        tmp = Path(tmp_name)
        handle = os.fdopen(fd, "w+b")
        try:
            fcntl.flock(handle.fileno(), fcntl.LOCK_SH)
            with open(source, "rb") as src:
                shutil.copyfileobj(src, handle, 1 << 20)
            handle.flush()
            os.fsync(handle.fileno())
            os.fchmod(handle.fileno(), 0o666 & ~_umask())
            if replace:
                os.replace(tmp, path)
            else:
                try:
                    os.link(tmp, path)
                except FileExistsError:
                    handle.close()
                    return None
        except BaseException:
            handle.close()
            raise
        finally:
            tmp.unlink(missing_ok=True)
        _fsync_directory(path.parent)
        return handle

    @contextlib.contextmanager
    def upload(self) -> Iterator[tuple[BinaryIO, Path]]:
        """A new temporary file for an upload's body, open for writing and held (a shared
        lock) until the block ends, then removed."""
        self.uploads.mkdir(parents=True, exist_ok=True)
        for _ in range(8):
            fd, name = tempfile.mkstemp(prefix=UPLOAD_PREFIX, suffix=".h5", dir=self.uploads)
            handle = os.fdopen(fd, "wb")
            fcntl.flock(handle.fileno(), fcntl.LOCK_SH)
            path = Path(name)
            if _same_file(handle, path):
                break
            handle.close()  # a cleaner starting meanwhile took it
        else:
            raise BoardError(f"{self.uploads}: expected a temporary file, found none kept")
        try:
            with handle:
                yield handle, path
        finally:
            path.unlink(missing_ok=True)

    def remove_orphans(
        self, referenced: Callable[[str], bool], known: Callable[[], set[str]]
    ) -> list[Path]:
        """Remove what killed processes left: uploads' temporary files, temporary copies in
        the store, and stored files that no submission refers to (not in ``known()``, the
        hashes referred to when the scan starts, and ``referenced(sha256)`` still False once
        the file is locked). Files in use are left.

        Returns:
            The files removed.
        """
        removed: list[Path] = []
        candidates: list[tuple[Path, str | None]] = []
        if self.uploads.is_dir():
            candidates += [(p, None) for p in sorted(self.uploads.glob(f"{UPLOAD_PREFIX}*"))]
        if self.files.is_dir():
            stored = known()
            for path in sorted(self.files.glob("*/*")):
                if _TMP_MARK in path.name:
                    candidates.append((path, None))
                elif _SHA.match(path.stem) and path.suffix == ".h5" and path.stem not in stored:
                    candidates.append((path, path.stem))
        for path, sha256 in candidates:
            if not path.is_file() or path.is_symlink():
                continue
            handle = _try_exclusive(path)
            if handle is None:
                continue
            with handle:
                if _same_file(handle, path) and (sha256 is None or not referenced(sha256)):
                    path.unlink()
                    removed.append(path)
        return removed
