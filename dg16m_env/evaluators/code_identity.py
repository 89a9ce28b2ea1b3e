"""Which code was scored: a sha256 of a classifier's or a policy's code and weights.

A submission file has a sha256; code handed to ``dg16m evaluate --classifier`` or ``--policy``
has none, yet a resumed run (``--resume``) must refuse a checkpoint or a stored result made by
other code. :func:`code_sha256` hashes what decides a subject's answers and can be read without
running it:

* its type's qualified name;
* the source file of the module that defines it (a function's module; for an instance, its
  class's module; for a bound method, its object's class's module);
* the weights of a torch ``Module``: the subject itself, or its ``policy`` attribute (a
  stable-baselines3 model), as the names, dtypes, shapes and bytes of its ``state_dict``;
* the value of a ``code_identity`` attribute (str) when the subject declares one: a subject whose
  answers depend on files it loads, or on modules other than its own, can name them there (for
  example the sha256 of its weights file).

What it does not see (other modules the code imports, files it reads) is not detected: after
changing those, remove the checkpoint (``R.<evaluator>.checkpoint/``) or run without
``--resume``.
"""

from __future__ import annotations

import hashlib
import inspect
import sys
from typing import Any

from .result import qualified_type

#: Bumped when what :func:`code_sha256` hashes changes (old checkpoints then do not match).
IDENTITY_VERSION = 1


def _defining_module(subject: Any) -> Any:
    """The module whose source defines ``subject`` (None when not found)."""
    owner = getattr(subject, "__self__", None)  # a bound method: its object's class
    if owner is not None and not inspect.ismodule(owner):
        subject = owner
    if not (inspect.isfunction(subject) or inspect.isclass(subject)):
        subject = type(subject)
    return sys.modules.get(getattr(subject, "__module__", "") or "")


def _source_bytes(module: Any) -> bytes:
    """The bytes of ``module``'s source file (empty for a built-in or an interactive one)."""
    try:
        path = inspect.getsourcefile(module) if module is not None else None
    except TypeError:  # a built-in module has no file
        path = None
    if not path:
        return b""
    try:
        with open(path, "rb") as handle:
            return handle.read()
    except OSError:  # a module whose file was removed since it was imported
        return b""


def _torch_module(subject: Any) -> Any:
    """The torch ``Module`` holding ``subject``'s weights: itself or its ``policy`` (None)."""
    torch = sys.modules.get("torch")  # a Module cannot exist unless torch was imported
    if torch is None:
        return None
    for candidate in (subject, getattr(subject, "policy", None)):
        if isinstance(candidate, torch.nn.Module):
            return candidate
    return None


def _update_with_weights(digest: Any, module: Any) -> None:
    """Add ``module``'s ``state_dict`` (names, dtypes, shapes, bytes; in its order)."""
    import torch

    for name, tensor in module.state_dict().items():
        value = tensor.detach().to("cpu").contiguous()
        digest.update(f"{name}|{value.dtype}|{tuple(value.shape)}\n".encode())
        digest.update(value.view(-1).view(torch.uint8).numpy().tobytes())


def code_sha256(subject: Any) -> str:
    """The sha256 (hex) of ``subject``'s code and weights (see the module docstring).

    Args:
        subject: a classifier or a policy (a callable, an object with ``predict``, a torch
            ``Module``).

    Returns:
        64 hex digits; the same code and weights give the same digest in any process.
    """
    digest = hashlib.sha256()
    digest.update(f"dg16m-code-identity {IDENTITY_VERSION}\n".encode())
    digest.update(f"type {qualified_type(subject)}\n".encode())
    source = _source_bytes(_defining_module(subject))
    digest.update(f"source {len(source)}\n".encode())
    digest.update(source)
    declared = getattr(subject, "code_identity", None)
    if isinstance(declared, str):
        digest.update(f"declared {declared}\n".encode())
    weights = _torch_module(subject)
    if weights is not None:
        digest.update(b"weights\n")
        _update_with_weights(digest, weights)
    return digest.hexdigest()
