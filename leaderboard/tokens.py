"""Team tokens: shown once, stored as a sha256, compared in constant time.

A token is ``dg16m_`` followed by 43 URL-safe characters (32 random bytes from
:mod:`secrets`). Only its sha256 is stored: a token carries 256 bits of entropy, so a plain
cryptographic hash is enough (a slow password hash protects guessable secrets, which these are
not). :func:`find_token` compares the presented token's hash with every stored one using
:func:`hmac.compare_digest` and never stops early, so the time taken does not depend on which
team (if any) matches.
"""

from __future__ import annotations

import hashlib
import hmac
import os
import re
import secrets
from collections.abc import Iterable
from typing import TypeVar

PREFIX = "dg16m_"
TOKEN_PATTERN = re.compile(r"^dg16m_[A-Za-z0-9_-]{43}$")
"""What a token looks like (anything else is refused before it is hashed)."""

T = TypeVar("T")


def new_token() -> str:
    """A fresh random token."""
    return PREFIX + secrets.token_urlsafe(32)


def token_sha256(token: str) -> str:
    """Hex sha256 of a token (what the store keeps)."""
    return hashlib.sha256(token.encode("utf-8")).hexdigest()


def find_token(token: str, stored: Iterable[tuple[str, T]]) -> T | None:
    """The value stored with ``token``'s hash, or None.

    Args:
        token: the presented token (any string; a malformed one matches nothing).
        stored: ``(token_sha256, value)`` pairs.
    """
    well_formed = bool(TOKEN_PATTERN.match(token))
    presented = token_sha256(token if well_formed else PREFIX).encode("ascii")
    found: T | None = None
    for digest, value in stored:
        if hmac.compare_digest(presented, digest.encode("ascii")) and well_formed:
            found = value
    return found


def write_token_file(path: str | os.PathLike[str], token: str, *, overwrite: bool = False) -> None:
    """Write ``token`` (and a newline) to a file only its owner can read (mode 0600).

    Raises:
        FileExistsError: ``path`` exists and ``overwrite`` is False.
    """
    flags = os.O_WRONLY | os.O_CREAT | (os.O_TRUNC if overwrite else os.O_EXCL)
    fd = os.open(path, flags, 0o600)
    with os.fdopen(fd, "w") as handle:
        handle.write(token + "\n")
