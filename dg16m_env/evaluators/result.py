"""What an evaluator returns: scores with object-resampled confidence intervals and the record
needed to reproduce them.

:class:`EvaluationResult` is JSON-ready (:meth:`EvaluationResult.to_dict`) and holds no clock
time, so the same inputs give the same bytes. Its record names the evaluator and its version,
the package version, the benchmark file's sha256, what was scored (e.g. a submission's sha256)
and every seed. :func:`breakdown` computes the per-object, per-family and overall rates that
every evaluator reports.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import MISSING, asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from dg16m_core.atomic import write_json_atomic
from dg16m_core.errors import Dg16mError
from dg16m_core.json_values import json_ready
from dg16m_env.rates import object_rate

#: ``format`` of a result file written by ``dg16m evaluate``.
RESULTS_FORMAT = "dg16m-evaluation"
RESULTS_VERSION = 1


class ResultError(Dg16mError, ValueError):
    """A malformed result (file or mapping)."""


@dataclass
class EvaluationResult:
    """One evaluator's scores of one subject.

    Attributes:
        evaluator: the registered name.
        evaluator_version: the evaluator's ``version``.
        package_version: the dg16m version that computed it.
        benchmark: ``{"sha256", "objects"}`` of the benchmark scored against (``{}`` when the
            evaluator uses none, e.g. a policy on an environment).
        subject: what was scored (kind, sha256 of a file, name of a callable, ...).
        parameters: every argument that can change a score (JSON-ready).
        seeds: every seed used, by name.
        headline: the key of :attr:`metrics` that ranks subjects.
        metrics: name -> rate with its confidence interval (``{"rate", "ci_low", "ci_high",
            "rows", "objects"}``, :func:`dg16m_env.rates.object_rate`) or a plain number.
        per_family: family -> metric name -> rate with confidence interval.
        per_object: object id -> metric name -> value (plus counts such as ``grasps``).
        failures: object id -> why it could not be scored (its grasps count as failures).
        details: evaluator-specific counts (e.g. FCE failure reasons), JSON-ready.
    """

    evaluator: str
    evaluator_version: str
    package_version: str
    benchmark: dict[str, Any]
    subject: dict[str, Any]
    parameters: dict[str, Any]
    seeds: dict[str, int]
    headline: str
    metrics: dict[str, Any]
    per_family: dict[str, dict[str, Any]] = field(default_factory=dict)
    per_object: dict[str, dict[str, Any]] = field(default_factory=dict)
    failures: dict[str, str] = field(default_factory=dict)
    details: dict[str, Any] = field(default_factory=dict)

    @property
    def partial(self) -> bool:
        """Whether it scored only some of the benchmark's objects (``dg16m evaluate --objects``
        / ``--limit``): such a result is never ranked beside full ones."""
        return bool(self.benchmark.get("partial") or self.benchmark.get("subset"))

    @property
    def score(self) -> float | None:
        """The headline rate (None when nothing was scored)."""
        value = self.metrics.get(self.headline)
        return value.get("rate") if isinstance(value, Mapping) else value

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready, keys sorted where they are ids (the same result gives the same JSON)."""
        out = asdict(self)
        for key in ("per_family", "per_object", "failures"):
            out[key] = dict(sorted(out[key].items()))
        return json_ready(out)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> EvaluationResult:
        """The result :meth:`to_dict` wrote.

        Raises:
            ResultError: not a mapping, or keys missing or unknown.
        """
        if not isinstance(data, Mapping):
            raise ResultError(f"result: expected a mapping, found {type(data).__name__}")
        known = {f.name for f in fields(cls)}
        required = {
            f.name for f in fields(cls) if f.default is MISSING and f.default_factory is MISSING
        }
        missing, unknown = sorted(required - set(data)), sorted(set(data) - known)
        if missing or unknown:
            raise ResultError(
                f"result: expected keys {sorted(known)}, found missing {missing} and unknown "
                f"{unknown}"
            )
        return cls(**dict(data))

    def format(self) -> str:
        """A few lines for a terminal: the metrics with their intervals, and failures."""
        lines = [
            f"{self.evaluator} v{self.evaluator_version} (dg16m {self.package_version})"
            + (f", benchmark {self.benchmark['sha256'][:12]}" if self.benchmark else "")
        ]
        if self.partial:
            lines.append(
                f"  PARTIAL: {self.benchmark.get('objects')} of the benchmark's "
                f"{self.benchmark.get('of', '?')} objects (not comparable with a full score)"
            )
        engine = (self.parameters or {}).get("simulator")
        if isinstance(engine, Mapping) and engine.get("name", "mujoco") != "mujoco":
            lines.append(f"  trials on MuJoCo Warp, device {engine.get('device', '?')}")
        for name, value in self.metrics.items():
            lines.append(f"  {name:<22} {format_rate(value)}")
        if self.failures:
            lines.append(f"  {len(self.failures)} objects could not be scored (counted as 0):")
            lines += [f"    {k}: {v}" for k, v in sorted(self.failures.items())[:5]]
        return "\n".join(lines)


def qualified_type(value: Any) -> str:
    """``module.QualName`` of a value's type (what a result records of code it scored)."""
    cls = type(value)
    return f"{cls.__module__}.{cls.__qualname__}"


def code_subject(kind: str, subject: Any, interface: str, sha256: str) -> dict[str, Any]:
    """What a result records of code it scored (a classifier, a policy): its kind, its ``name``
    attribute when that is a string, its type, the interface it was called through and the
    sha256 of its code and weights (:func:`dg16m_env.evaluators.code_identity.code_sha256`)."""
    name = getattr(subject, "name", None)
    return {
        "kind": kind,
        "name": name if isinstance(name, str) else None,
        "type": qualified_type(subject),
        "interface": interface,
        "sha256": sha256,
    }


def format_rate(value: Any) -> str:
    """``"76.3% [72.1, 80.2] (3000 rows, 300 objects)"`` for a rate dict, else the number."""
    if isinstance(value, Mapping) and "rate" in value:
        if value["rate"] is None:
            return "n/a (nothing scored)"
        return (
            f"{100 * value['rate']:.1f}% [{100 * value['ci_low']:.1f}, "
            f"{100 * value['ci_high']:.1f}] ({_counted(value)})"
        )
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def _counted(value: Mapping[str, Any]) -> str:
    if value.get("objects") is None:  # e.g. episodes of an environment without objects
        return f"{value['rows']} episodes"
    return f"{value['rows']} rows, {value['objects']} objects"


def breakdown(
    values: Mapping[str, np.ndarray],
    object_index: np.ndarray,
    object_ids: Sequence[str],
    families: Sequence[str],
    *,
    rows: Mapping[str, np.ndarray] | None = None,
    n_resamples: int = 2000,
    seed: int = 0,
) -> tuple[dict[str, Any], dict[str, dict[str, Any]], dict[str, dict[str, Any]]]:
    """Overall, per-family and per-object means of per-row values.

    Args:
        values: metric name -> (N,) per-row value (a 0/1 verdict, a probability).
        object_index: (N,) index into ``object_ids`` of each row.
        object_ids: the O object ids.
        families: the O families ("" for meshes: grouped as ``"(none)"``).
        rows: metric name -> (N,) bool rows that count (default all), e.g. valid trials only.
        n_resamples: object resamples of the confidence intervals.
        seed: seed of the resampling.

    Returns:
        ``(metrics, per_family, per_object)`` as in :class:`EvaluationResult`.
    """
    object_index = np.asarray(object_index)
    rows = rows or {}
    metrics = {
        name: object_rate(v, object_index, rows.get(name), n_resamples, seed)
        for name, v in values.items()
    }
    family_of_row = np.array([families[i] or "(none)" for i in object_index], dtype=object)
    per_family: dict[str, dict[str, Any]] = {}
    for family in sorted(set(family_of_row.tolist())):
        in_family = family_of_row == family
        per_family[family] = {
            name: object_rate(
                v,
                object_index,
                in_family & np.asarray(rows.get(name, in_family), dtype=bool),
                n_resamples,
                seed,
            )
            for name, v in values.items()
        }
    per_object: dict[str, dict[str, Any]] = {}
    for k, object_id in enumerate(object_ids):
        mine = object_index == k
        entry: dict[str, Any] = {"grasps": int(mine.sum())}
        for name, v in values.items():
            counted = mine & np.asarray(rows.get(name, mine), dtype=bool)
            entry[name] = float(np.mean(v[counted])) if counted.any() else None
        per_object[object_id] = entry
    return metrics, per_family, per_object


def object_means(per_object: Mapping[str, Mapping[str, Any]], names: Sequence[str]) -> dict:
    """Each metric's mean over objects (every object weighs the same, whatever its number of
    grasps; objects where the metric is undefined are left out): shown beside the pooled rates,
    so a submission that puts many grasps on easy objects and one on hard ones is visible."""
    out: dict[str, float | None] = {}
    for name in names:
        values = [e[name] for e in per_object.values() if e.get(name) is not None]
        out[name] = float(np.mean(values)) if values else None
    return out


def write_results(
    path: str | os.PathLike[str],
    results: Mapping[str, EvaluationResult],
    subject: Mapping[str, Any] | None = None,
) -> Path:
    """Write several evaluators' results as one JSON file (atomically: a temporary file renamed
    over ``path``, so a reader or an interrupt never sees half a file):
    ``{"format", "version", "subject", "results": {name: result}}``. ``dg16m evaluate`` calls it
    after each evaluator finishes, so an interrupted run keeps what was done."""
    payload = {
        "format": RESULTS_FORMAT,
        "version": RESULTS_VERSION,
        "subject": json_ready(dict(subject or {})),
        "results": {name: r.to_dict() for name, r in results.items()},
    }
    write_json_atomic(path, payload)
    return Path(path)


def read_results(path: str | os.PathLike[str]) -> dict[str, EvaluationResult]:
    """The results :func:`write_results` wrote.

    Raises:
        ResultError: not JSON, another format or version, or a malformed result.
    """
    return {
        name: EvaluationResult.from_dict(r) for name, r in _read_payload(path)["results"].items()
    }


def read_results_file(
    path: str | os.PathLike[str],
) -> tuple[dict[str, Any], dict[str, EvaluationResult]]:
    """The subject record and the results :func:`write_results` wrote.

    Raises:
        ResultError: as :func:`read_results`.
    """
    data = _read_payload(path)
    subject = data.get("subject")
    results = {name: EvaluationResult.from_dict(r) for name, r in data["results"].items()}
    return (dict(subject) if isinstance(subject, dict) else {}), results


def _read_payload(path: str | os.PathLike[str]) -> dict[str, Any]:
    """A results file's JSON, its format, version and ``results`` mapping checked."""
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ResultError(f"{path}: expected a JSON results file, found {exc}") from None
    if not isinstance(data, dict) or data.get("format") != RESULTS_FORMAT:
        raise ResultError(f"{path}: expected format {RESULTS_FORMAT!r}, found another file")
    if data.get("version") != RESULTS_VERSION:
        raise ResultError(
            f"{path}: expected version {RESULTS_VERSION}, found {data.get('version')!r}"
        )
    results = data.get("results")
    if not isinstance(results, dict):
        raise ResultError(f"{path}: expected a 'results' mapping, found {type(results).__name__}")
    return data
