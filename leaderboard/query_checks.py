"""The board's errors, and the checks of what enters it: team names, file names, labels,
evaluator names, ids, and a request's query parameters (each refused with ``expected ...,
found ...``).

Every error is a :class:`BoardError` whose :attr:`~BoardError.status` is the HTTP status the
service answers with. The service's routes (:mod:`leaderboard.routes`) check their query with
:func:`check_query` and :func:`query_number`, the one place those checks are written.

Was ``leaderboard.checks`` before 0.2.0 (that name still imports, with a
:class:`DeprecationWarning`, for one release).
"""

from __future__ import annotations

import re
from collections.abc import Collection, Sequence
from typing import Any

from dg16m_core.errors import Dg16mError

TEAM_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9 ._-]{0,63}$")
"""Team names: 1-64 letters, digits, space, dot, underscore, hyphen; not starting with a sign."""
FILE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,127}$")
"""Uploaded file names: a plain name (no folders, no ``..``, no spaces or control characters)."""
LABEL_CHARS = 80
"""Longest label (the name shown on the board)."""
MAX_ID = 2**63 - 1
"""Largest id SQLite stores (a signed 64-bit integer); ids are 1 .. MAX_ID."""
DIGITS = re.compile(r"^[0-9]{1,19}$")
"""1 to 19 decimal digits: an id, a page number or size, a ``Content-Length``."""


class BoardError(Dg16mError, ValueError):
    """A request the board refuses; :attr:`status` is the HTTP status the service answers."""

    status = 400


class NotFoundError(BoardError):
    """No such team or submission."""

    status = 404


class ForbiddenError(BoardError):
    """A team asked for another team's submission."""

    status = 403


class InvalidParameterError(BoardError):
    """A query parameter out of its bounds (a page number, a page size)."""

    status = 422


class DuplicateError(BoardError):
    """The same file with the same evaluators was already submitted by this team."""

    status = 409

    def __init__(self, message: str, submission_id: int):
        super().__init__(message)
        self.submission_id = submission_id


def check_id(value: Any, what: str = "submission") -> int:
    """``value`` as an id (an int, or a string of decimal digits) in 1 .. :data:`MAX_ID`.

    Raises:
        NotFoundError: anything else (no row can have that id), saying what an id is.
    """
    number: int | None = None
    if isinstance(value, int) and not isinstance(value, bool):
        number = value
    elif isinstance(value, str) and DIGITS.match(value):
        number = int(value)
    if number is None or not 1 <= number <= MAX_ID:
        if isinstance(value, int) and not isinstance(value, bool):
            text = (
                str(value) if value.bit_length() < 1000 else f"an int of {value.bit_length()} bits"
            )
        else:
            text = repr(value if isinstance(value, str) else type(value).__name__)
        shown = text if len(text) <= 40 else f"{text[:40]}... ({len(text)} characters)"
        raise NotFoundError(
            f"{what}: expected an id from 1 to {MAX_ID} (a positive 64-bit integer), found {shown}"
        )
    return number


def check_team_name(name: Any) -> str:
    """``name`` if it is a valid team name.

    Raises:
        BoardError: anything else, saying what a name may hold.
    """
    if not isinstance(name, str) or not TEAM_NAME.match(name) or name != name.strip():
        raise BoardError(
            "team: expected 1-64 letters, digits, spaces, '.', '_' or '-' starting with a "
            f"letter or digit, found {name!r}"
        )
    return name


def check_file_name(name: Any) -> str:
    """``name`` if it is a plain file name (what an upload may call itself).

    Raises:
        BoardError: a path (``/``, ``\\``, ``..``), an empty or hidden name, odd characters.
    """
    if not isinstance(name, str) or not FILE_NAME.match(name) or ".." in name:
        raise BoardError(
            "file name: expected a plain name of letters, digits, '.', '_' and '-' (like "
            f"mine.h5, no folders), found {str(name)[:200]!r}"
        )
    return name


def check_label(label: Any) -> str:
    """A label for the board: printable, at most :data:`LABEL_CHARS` characters.

    Raises:
        BoardError: not a string, empty, too long or with control characters.
    """
    if (
        not isinstance(label, str)
        or not label.strip()
        or len(label) > LABEL_CHARS
        or not label.isprintable()
    ):
        raise BoardError(
            f"label: expected 1-{LABEL_CHARS} printable characters, found {str(label)[:200]!r}"
        )
    return label.strip()


def check_evaluators(names: Sequence[str] | str) -> list[str]:
    """Registered evaluators of submission files, in the given order, without repeats.

    Raises:
        BoardError: an unknown name, or an evaluator of something else than submissions.
    """
    from dg16m_env.evaluators import evaluator_class
    from dg16m_env.evaluators import names as registered

    if isinstance(names, str):
        names = [n.strip() for n in names.split(",") if n.strip()]
    out: list[str] = []
    for name in names:
        if name not in registered():
            raise BoardError(
                f"evaluators: expected names of {', '.join(registered())}, found {str(name)[:80]!r}"
            )
        kind = evaluator_class(name).subject_kind
        if kind != "submission":
            raise BoardError(
                f"evaluators: expected evaluators of submission files, found {name!r} (it "
                f"scores a {kind})"
            )
        if name not in out:
            out.append(name)
    if not out:
        raise BoardError("evaluators: expected at least one name (e.g. fce,gsr), found none")
    return out


def check_query(
    params: Any,
    allowed: Collection[str],
    *,
    error: type[BoardError] = InvalidParameterError,
    shown: int | None = 10,
    once: bool = True,
) -> None:
    """Refuse a query (a Starlette ``QueryParams``) with keys outside ``allowed`` or, when
    ``once``, one of them repeated.

    Args:
        params: the request's query parameters (``keys()`` and ``getlist(key)``).
        allowed: the keys the route takes.
        error: the error raised (its status is the answer's: 422 for the board's pages, 400
            for an upload).
        shown: at most this many unknown keys named in the message (None: all of them).
        once: refuse an allowed key given more than once.

    Raises:
        BoardError: an ``error`` saying which keys were expected and which came.
    """
    unknown = sorted(set(params) - set(allowed))
    if unknown:
        raise error(
            f"query: expected only {sorted(allowed)}, found {[k[:40] for k in unknown[:shown]]}"
        )
    if once:
        for key in allowed:
            if len(params.getlist(key)) > 1:
                raise error(f"query: expected {key!r} once, found it repeated")


def query_number(params: Any, key: str, default: int) -> int:
    """The query parameter ``key`` as a number of 1 to 19 decimal digits; ``default`` when
    absent (its bounds are the caller's).

    Raises:
        InvalidParameterError: (422) anything but decimal digits.
    """
    value = params.get(key)
    if value is None:
        return default
    if not DIGITS.match(value):
        raise InvalidParameterError(
            f"{key}: expected a positive integer, found {value[:40]!r}"
            + ("..." if len(value) > 40 else "")
        )
    return int(value)
