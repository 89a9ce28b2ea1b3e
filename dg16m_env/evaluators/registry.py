"""The evaluator registry: ``register(name)``, ``make(name, **kwargs)``, ``names()``.

An evaluator is a class derived from :class:`Evaluator` with a ``version``; its constructor takes
keyword arguments (the benchmark, workers, seeds, ...) and its :meth:`Evaluator.evaluate` scores
one subject (a submission, a classifier, a policy) and returns an
:class:`~dg16m_env.evaluators.result.EvaluationResult`. Registering it makes it available to
``dg16m evaluate --evaluators NAME`` and the leaderboard::

    from dg16m_env.evaluators import Evaluator, register

    @register("my_metric")
    class MyMetric(Evaluator):
        version = "1"

        def evaluate(self, subject):
            ...
"""

from __future__ import annotations

import abc
import inspect
from collections.abc import Callable
from typing import Any, ClassVar, TypeVar

from dataset_gen.io import package_version
from dg16m_core.errors import Dg16mError

from .result import EvaluationResult


class EvaluatorError(Dg16mError, ValueError):
    """An unknown evaluator, a bad registration, bad evaluator arguments or a subject it cannot
    score."""


class Evaluator(abc.ABC):
    """Base class of the registered evaluators.

    Attributes:
        name: the registered name (set by :func:`register`).
        version: bump it whenever a change can change a score; every result records it.
        subject_kind: what :meth:`evaluate` takes (``"submission"``, ``"classifier"``,
            ``"policy"``), shown by ``dg16m evaluate --list``.
    """

    name: ClassVar[str] = ""
    version: ClassVar[str] = ""
    subject_kind: ClassVar[str] = ""

    @abc.abstractmethod
    def evaluate(self, subject: Any) -> EvaluationResult:
        """Score ``subject``; the same subject and arguments give the same result."""

    def __call__(self, subject: Any) -> EvaluationResult:
        return self.evaluate(subject)

    def planned(self) -> dict[str, Any] | None:
        """The fields every result of this evaluator, as configured, will hold whatever the
        subject (``evaluator``, ``evaluator_version``, ``package_version``, ``benchmark``,
        ``parameters``, ``seeds``), or None when it cannot tell before scoring. ``dg16m evaluate
        --resume`` keeps a stored result only when these fields and the subject's sha256 match
        it."""
        return None

    def identity(self) -> dict[str, str]:
        """What every result of this evaluator records of who made it: its name, its version and
        the package version."""
        return {
            "evaluator": self.name,
            "evaluator_version": self.version,
            "package_version": package_version(),
        }

    def result(self, **fields: Any) -> EvaluationResult:
        """An :class:`EvaluationResult` of this evaluator: ``fields`` plus :meth:`identity`."""
        return EvaluationResult(**self.identity(), **fields)

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r}, version={self.version!r})"


E = TypeVar("E", bound=type[Evaluator])

_REGISTRY: dict[str, type[Evaluator]] = {}


def register(name: str) -> Callable[[E], E]:
    """Class decorator: register an :class:`Evaluator` subclass under ``name``.

    Raises:
        EvaluatorError: ``name`` is not a lower-case identifier, is taken by another class, or
            the class is not an :class:`Evaluator` with a non-empty ``version``.
    """
    if not isinstance(name, str) or not name.isidentifier() or name != name.lower():
        raise EvaluatorError(f"name: expected a lower-case identifier, found {name!r}")

    def decorate(cls: E) -> E:
        if not (inspect.isclass(cls) and issubclass(cls, Evaluator)):
            raise EvaluatorError(f"{name}: expected a subclass of Evaluator, found {cls!r}")
        if not isinstance(cls.version, str) or not cls.version:
            raise EvaluatorError(
                f"{name}: expected a non-empty version string, found {cls.version!r}"
            )
        known = _REGISTRY.get(name)
        if known is not None and known.__qualname__ != cls.__qualname__:
            raise EvaluatorError(f"{name}: already registered to {known.__qualname__}")
        cls.name = name
        _REGISTRY[name] = cls
        return cls

    return decorate


def names() -> list[str]:
    """The registered evaluator names, sorted."""
    return sorted(_REGISTRY)


def evaluator_class(name: str) -> type[Evaluator]:
    """The class registered under ``name``.

    Raises:
        EvaluatorError: unknown name (the message lists the known ones).
    """
    try:
        return _REGISTRY[name]
    except KeyError:
        raise EvaluatorError(
            f"evaluator: expected one of {', '.join(names())}, found {name!r}"
        ) from None


def make(name: str, **kwargs: Any) -> Evaluator:
    """A new evaluator ``name`` configured by ``kwargs`` (see each evaluator's docstring).

    Raises:
        EvaluatorError: unknown name, or an argument the evaluator does not take.
    """
    cls = evaluator_class(name)
    accepted = inspect.signature(cls).parameters
    takes_any = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in accepted.values())
    unknown = sorted(set(kwargs) - set(accepted))
    if unknown and not takes_any:
        raise EvaluatorError(
            f"{name}: expected arguments among {sorted(accepted)}, found unknown {unknown}"
        )
    return cls(**kwargs)
