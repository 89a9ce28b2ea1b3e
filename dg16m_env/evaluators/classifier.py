"""``classifier``: how well a grasp classifier ranks the benchmark's candidates (the paper's
Table II protocol).

The subject
-----------
A classifier scores the stored candidate dual grasps of one object; higher = more likely to
succeed (only the order of the scores matters). It is one of:

(a) a callable ``classifier(observation, poses) -> scores``:

    * ``observation``: the object's observation, a ``dict``
      (:func:`dg16m_env.subjects.observation.object_observation`: ``object_id``, ``family``, ``points``
      (P, 3) float32 m, ``normals`` (P, 3) float32, ``bounds`` (2, 3) float64 m,
      ``mesh_vertices`` (V, 3) float64 m, ``mesh_faces`` (F, 3) int64; object frame). It is a
      fresh copy for every call: the classifier may modify it.
    * ``poses``: (N, 2, 4, 4) float64 hand poses (Panda grasp frame -> object frame, m) of ALL
      the object's candidates (every arm), a fresh C-contiguous copy.
    * returns ``scores``: anything ``numpy.asarray`` turns into an (N,) array of finite numbers
      (a list, a numpy array, a CPU tensor without grad).

(b) a ``torch.nn.Module`` whose ``forward(points, poses) -> scores`` takes ``points`` (P, 3)
    float32 (the observation's cloud) and ``poses`` (n, 2, 4, 4) float32 (a chunk of at most
    ``batch_size`` candidates) and returns (n,) logits or probabilities. The evaluator calls it
    on the CPU (its parameters must be there), in eval mode under ``torch.no_grad()``, and
    restores every submodule's training mode afterwards. torch is imported only for such a
    subject (the evaluator runs without torch installed).

A ``name`` attribute (str), when present, is recorded in the result's ``subject``.

What is measured
----------------
For every object the candidates are presented in a seeded random order (``candidate_seed``):
the stored rows are grouped by arm (``fc_pass`` first), and a classifier that saw them in that
order could score by position (a constant classifier would get the stored order's top-k, 99.7%
FCE and 70.8% GSR on the shipped benchmark, against 97.2% / 44.2% for ranking by the true p /
at random). They are ranked by score, descending; ties keep the presented order (stable sort).

Metrics (``k`` and each level of ``levels``; overall with object-resampled 95 % intervals
(:func:`dg16m_env.rates.object_rate`), per family and per object):

* ``fce_top{k}``: mean stored ``fc_passed`` of the top-k candidates per object (Table II's FCE);
* ``gsr_top{k}_{level}``: mean stored success probability of the top-k (the headline is
  ``gsr_top{k}_full``, or the first level's when ``"full"`` is not measured);
* ``precision_at_{k}_{level}``: mean binary label (``p >= 0.5``) of the top-k;
* ``ap_{level}``: average precision of an object's scores against its binary labels
  (sum over the positives of the precision at their rank / number of positives), averaged over
  the objects that have a positive (the others are counted in ``details``), with an interval
  from resampling those objects.

An object with fewer than k candidates contributes all of them. An object the classifier fails
on (it raises an ``Exception``, returns scores of another shape or non-finite scores) is listed
in ``failures`` with the reason and counts as 0: its top-k rows are failures (never dropped from
the denominators) and its AP is 0. ``details["chance"]`` holds what a random ranking gets in
expectation: the mean over objects of the object's mean ``fc_passed`` / p / label (AP: the
positive fraction, an approximation of a random ranking's AP).

Arguments of ``make("classifier", ...)``: ``benchmark`` (path or :class:`BenchmarkRef`, default
the embedded benchmark), ``mesh_root`` (mesh benchmarks), ``k``, ``levels``, ``n_points`` and
``observation_seed`` (the observations' clouds), ``batch_size`` (torch modules),
``candidate_seed`` (the order the candidates are presented in), ``n_resamples`` and ``seed`` (the intervals),
``progress``.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from dataset_gen.sources.object_source import object_seed
from dg16m_core.checks import check_integer
from dg16m_core.errors import Dg16mError
from dg16m_core.progress import progress_bar
from dg16m_env.benchmark.ref import BenchmarkRef, load_benchmark_ref
from dg16m_env.physics.labels import LEVELS
from dg16m_env.rates import object_rate
from dg16m_env.subjects.observation import object_observation

from .checkpoint import CheckpointError, CheckpointRequest, ObjectCheckpoint
from .code_identity import code_sha256
from .registry import Evaluator, EvaluatorError, register
from .result import EvaluationResult, breakdown, code_subject, qualified_type


class ScoreError(Exception):
    """A classifier's scores for one object cannot be used (the object is a failure)."""


def average_precision(scores: np.ndarray, labels: np.ndarray) -> float | None:
    """Average precision of one ranking: sum over the positives of the precision at their rank,
    divided by the number of positives; ties keep the given order (stable).

    Args:
        scores: (N,) finite scores, higher = ranked first.
        labels: (N,) bool binary labels.

    Returns:
        AP in [0, 1], or None when there is no positive (undefined).
    """
    labels = np.asarray(labels, dtype=bool)
    order = np.argsort(-np.asarray(scores, dtype=np.float64), kind="stable")
    ranked = labels[order]
    n_pos = int(ranked.sum())
    if n_pos == 0:
        return None
    precision = np.cumsum(ranked) / np.arange(1, ranked.size + 1)
    return float(precision[ranked].sum() / n_pos)


def _is_torch_module(subject: Any) -> bool:
    torch = sys.modules.get("torch")  # a Module cannot exist unless torch was imported
    return torch is not None and isinstance(subject, torch.nn.Module)


def _as_scores(raw: Any, n: int) -> np.ndarray:
    """``raw`` as (n,) finite float64 scores.

    Raises:
        ScoreError: not numeric, another shape, or NaN / infinite values.
    """
    try:
        scores = np.asarray(raw, dtype=np.float64)
    except (TypeError, ValueError, RuntimeError) as exc:
        raise ScoreError(
            f"scores: expected ({n},) numbers, found {type(raw).__name__} ({exc})"
        ) from None
    if scores.shape != (n,):
        raise ScoreError(f"scores: expected shape ({n},), found {scores.shape}")
    bad = int((~np.isfinite(scores)).sum())
    if bad:
        raise ScoreError(f"scores: expected finite values, found {bad} NaN or infinite of {n}")
    return scores


def _module_scorer(module: Any, batch_size: int) -> Callable[[dict[str, Any], np.ndarray], Any]:
    """A callable classifier that runs ``module`` on CPU tensors in chunks of ``batch_size``."""
    import torch

    def score(observation: dict[str, Any], poses: np.ndarray) -> np.ndarray:
        points = torch.from_numpy(np.ascontiguousarray(observation["points"], dtype=np.float32))
        out = []
        for start in range(0, len(poses), batch_size):
            chunk = torch.from_numpy(
                np.ascontiguousarray(poses[start : start + batch_size], dtype=np.float32)
            )
            result = module(points, chunk)
            if not isinstance(result, torch.Tensor):
                raise ScoreError(
                    f"forward: expected a Tensor ({len(chunk)},), found {type(result).__name__}"
                )
            if tuple(result.shape) != (len(chunk),):
                raise ScoreError(
                    f"forward: expected shape ({len(chunk)},) for {len(chunk)} poses, found "
                    f"{tuple(result.shape)}"
                )
            out.append(result.detach().to("cpu", torch.float64).numpy())
        return np.concatenate(out) if out else np.zeros(0)

    return score


def _top_k(scores: np.ndarray, k: int) -> np.ndarray:
    """Indices of the ``k`` highest scores, descending, ties in the given order."""
    return np.argsort(-scores, kind="stable")[:k]


@register("classifier")
class ClassifierEvaluator(Evaluator):
    """Top-k FCE / GSR, precision@k and AP of a classifier's ranking (see the module
    docstring)."""

    version = "1"
    subject_kind = "classifier"

    def __init__(
        self,
        *,
        benchmark: str | os.PathLike[str] | BenchmarkRef | None = None,
        mesh_root: str | os.PathLike[str] | None = None,
        k: int = 10,
        levels: Sequence[str] = ("full", "gravity"),
        n_points: int = 2048,
        observation_seed: int = 0,
        batch_size: int = 4096,
        candidate_seed: int = 0,
        n_resamples: int = 2000,
        seed: int = 0,
        progress: bool = False,
    ) -> None:
        self.k = check_integer("k", k, minimum=1, error=EvaluatorError)
        levels = tuple(levels) if isinstance(levels, (list, tuple)) else (levels,)
        if not levels or len(set(levels)) != len(levels) or not set(levels) <= set(LEVELS):
            raise EvaluatorError(
                f"levels: expected distinct levels among {LEVELS}, found {list(levels)}"
            )
        self.levels = levels
        self.n_points = check_integer("n_points", n_points, minimum=1, error=EvaluatorError)
        self.observation_seed = check_integer(
            "observation_seed", observation_seed, minimum=0, error=EvaluatorError
        )
        self.batch_size = check_integer("batch_size", batch_size, minimum=1, error=EvaluatorError)
        self.candidate_seed = check_integer(
            "candidate_seed", candidate_seed, minimum=0, error=EvaluatorError
        )
        self.n_resamples = check_integer(
            "n_resamples", n_resamples, minimum=1, error=EvaluatorError
        )
        self.seed = check_integer("seed", seed, minimum=0, error=EvaluatorError)
        self.progress = bool(progress)
        self.ref = load_benchmark_ref(benchmark, mesh_root)
        root = mesh_root if mesh_root is not None else self.ref.mesh_root
        self.mesh_root = str(root) if root is not None else None
        meshes = [
            o.object_id for o in self.ref.benchmark.objects if not o.family and not o.has_mesh
        ]
        if meshes and self.mesh_root is None:
            raise EvaluatorError(
                f"mesh_root: expected the mesh folder of the benchmark's {len(meshes)} mesh "
                f"objects (e.g. {meshes[0]!r}), found none"
            )
        self._observations: dict[int, dict[str, Any] | str] = {}

    @property
    def headline(self) -> str:
        level = "full" if "full" in self.levels else self.levels[0]
        return f"gsr_top{self.k}_{level}"

    def _observation(self, index: int) -> dict[str, Any]:
        """A fresh copy of object ``index``'s observation (built once, then cached).

        Raises:
            ScoreError: the object cannot be loaded (a broken mesh).
        """
        cached = self._observations.get(index)
        if cached is None:
            obj = self.ref.benchmark.objects[index]
            try:
                cached = object_observation(
                    obj.load(self.mesh_root), n_points=self.n_points, seed=self.observation_seed
                )
            except Dg16mError as exc:  # a broken mesh fails only its own object
                cached = f"object could not be loaded: {type(exc).__name__}: {exc}"
            self._observations[index] = cached
        if isinstance(cached, str):
            raise ScoreError(cached)
        return {k: v.copy() if isinstance(v, np.ndarray) else v for k, v in cached.items()}

    def _order(self, index: int, n: int) -> np.ndarray:
        """(n,) the order in which object ``index``'s candidates are presented."""
        object_id = self.ref.benchmark.objects[index].object_id
        rng = np.random.default_rng(object_seed(self.candidate_seed, f"candidates:{object_id}"))
        return rng.permutation(n)

    def run_parameters(self) -> dict[str, Any]:
        """Every argument that can change a score (a result's ``parameters``)."""
        return {
            "k": self.k,
            "levels": list(self.levels),
            "n_points": self.n_points,
            "observation_seed": self.observation_seed,
            "batch_size": self.batch_size,
            "n_resamples": self.n_resamples,
        }

    def run_seeds(self) -> dict[str, int]:
        """Every seed used, by name (a result's ``seeds``)."""
        return {
            "observation": self.observation_seed,
            "resample": self.seed,
            "candidates": self.candidate_seed,
        }

    def planned(self) -> dict[str, Any]:
        """See :meth:`Evaluator.planned`."""
        from dg16m_core.json_values import json_ready

        return json_ready(
            {
                **self.identity(),
                "benchmark": self.ref.record(),
                "parameters": self.run_parameters(),
                "seeds": self.run_seeds(),
            }
        )

    def evaluate(
        self, subject: Any, *, checkpoint: CheckpointRequest | None = None
    ) -> EvaluationResult:
        """Score ``subject`` (a classifier, see the module docstring). With ``checkpoint``, each
        object's ranking (or failure) is recorded in its folder as it is scored, and a resumed
        run (``checkpoint.resume``) scores only the objects not recorded there; the result is
        the same as without (see :mod:`dg16m_env.evaluators.checkpoint`; the subject is told
        apart by :func:`~dg16m_env.evaluators.code_identity.code_sha256`).

        Raises:
            EvaluatorError: the subject is neither callable nor a torch Module, or a Module has
                parameters outside the CPU.
            CheckpointError: resuming a checkpoint of another run (subject, benchmark,
                parameters, seeds or versions).
        """
        module = _is_torch_module(subject)
        if module:
            devices = sorted(
                {str(t.device) for t in (*subject.parameters(), *subject.buffers())} - {"cpu"}
            )
            if devices:
                raise EvaluatorError(
                    f"classifier: expected a torch module on the CPU, found tensors on "
                    f"{devices} (call .cpu() first)"
                )
        elif not callable(subject):
            raise EvaluatorError(
                "classifier: expected a callable classifier(observation, poses) -> scores or a "
                f"torch.nn.Module, found {qualified_type(subject)}"
            )
        sha256 = code_sha256(subject)
        store = None
        if checkpoint is not None:
            store = ObjectCheckpoint(checkpoint, {**self.planned(), "subject": sha256})
        if module:
            import torch

            modes = [(m, m.training) for m in subject.modules()]
            subject.eval()
            try:
                with torch.no_grad():
                    scorer = _module_scorer(subject, self.batch_size)
                    scores, failures = self._score_all(scorer, store)
            finally:
                for m, training in modes:
                    m.training = training
        else:
            scores, failures = self._score_all(subject, store)
        result = self._result(subject, module, scores, failures, sha256)
        if store is not None:
            store.finish()
        return result

    def _score_all(
        self,
        classifier: Callable[[dict[str, Any], np.ndarray], Any],
        store: ObjectCheckpoint | None = None,
    ) -> tuple[dict[int, np.ndarray], dict[str, str]]:
        """Each object's (N_o,) scores in stored row order, or its failure reason; the objects
        ``store`` kept are not scored again, and each scored one is recorded there."""
        bench = self.ref.benchmark
        ids = [obj.object_id for obj in bench.objects]
        scores, failures = self._kept(store, ids)
        objects = [i for i in range(len(ids)) if i not in scores and ids[i] not in failures]
        for index in progress_bar(objects, desc="classifier", enabled=self.progress):
            rows = np.flatnonzero(bench.object_index == index)
            if rows.size == 0:
                continue  # nothing to rank: no top-k rows, AP undefined
            try:
                scores[index] = self._ranked(classifier, index, rows)
            except ScoreError as exc:
                failures[ids[index]] = str(exc)
            except Exception as exc:  # the classifier's own error fails only this object
                failures[ids[index]] = f"{type(exc).__name__}: {exc}"
            if store is not None:
                if index in scores:
                    store.save(index, ids[index], {"scores": scores[index]})
                else:
                    store.save(index, ids[index], error=failures[ids[index]])
        # in benchmark order, whichever run scored them (the result's bytes do not depend on it)
        return scores, {i: failures[i] for i in ids if i in failures}

    def _ranked(
        self,
        classifier: Callable[[dict[str, Any], np.ndarray], Any],
        index: int,
        rows: np.ndarray,
    ) -> np.ndarray:
        """Object ``index``'s (N_o,) scores in stored row order: minus the rank the classifier
        gave each of its candidates ``rows``, shown in the seeded order.

        Raises:
            ScoreError: the object cannot be loaded, or the scores cannot be used.
        """
        order = self._order(index, rows.size)
        observation = self._observation(index)
        poses = np.ascontiguousarray(self.ref.benchmark.poses[rows[order]], dtype=np.float64)
        presented = _as_scores(classifier(observation, poses), rows.size)
        # Stored-order scores; ties must keep the presented order, so rank here by rank.
        rank = np.empty(rows.size, dtype=np.int64)
        rank[order[_top_k(presented, rows.size)]] = np.arange(rows.size)
        return -rank.astype(np.float64)  # distinct: higher = ranked first

    def _kept(
        self, store: ObjectCheckpoint | None, ids: list[str]
    ) -> tuple[dict[int, np.ndarray], dict[str, str]]:
        """The scores and failures of the objects a resumed checkpoint holds."""
        scores: dict[int, np.ndarray] = {}
        failures: dict[str, str] = {}
        if store is None:
            return scores, failures
        position = {object_id: k for k, object_id in enumerate(ids)}
        for object_id, entry in store.kept(ids).items():
            index = position[object_id]
            if entry["error"] is not None:
                failures[object_id] = str(entry["error"])
                continue
            found = entry["arrays"].get("scores")
            n = int((self.ref.benchmark.object_index == index).sum())
            if found is None or found.shape != (n,) or found.dtype != np.float64:
                raise CheckpointError(
                    f"classifier checkpoint of {object_id}: expected ({n},) float64 scores, "
                    f"found {None if found is None else (found.shape, str(found.dtype))}; "
                    "remove the checkpoint folder or run without --resume"
                )
            scores[index] = found
        if scores or failures:
            print(
                f"classifier: resuming: {len(scores) + len(failures)} of {len(ids)} objects "
                f"kept from {store.folder}",
                file=sys.stderr,
            )
        return scores, failures

    def _result(
        self,
        subject: Any,
        module: bool,
        scores: dict[int, np.ndarray],
        failures: dict[str, str],
        sha256: str,
    ) -> EvaluationResult:
        bench, ref, k = self.ref.benchmark, self.ref, self.k
        ids, families = ref.object_ids, ref.families
        p = {level: bench.p(level) for level in self.levels}
        label = {level: bench.label(level) for level in self.levels}
        top_rows: list[np.ndarray] = []  # benchmark rows of the top k, -1 for a failed object
        top_index: list[np.ndarray] = []
        ap: dict[str, dict[int, float]] = {level: {} for level in self.levels}
        no_positive: dict[str, list[str]] = {level: [] for level in self.levels}
        chance_rows: list[np.ndarray] = []
        for index, object_id in enumerate(ids):
            rows = np.flatnonzero(bench.object_index == index)
            if rows.size == 0:
                continue
            take = min(k, rows.size)
            chance_rows.append(rows)
            top_index.append(np.full(take, index))
            mine = scores.get(index)
            top_rows.append(rows[_top_k(mine, take)] if mine is not None else np.full(take, -1))
            for level in self.levels:
                if not label[level][rows].any():
                    no_positive[level].append(object_id)
                elif mine is None:
                    ap[level][index] = 0.0
                else:
                    ap[level][index] = average_precision(mine, label[level][rows])
        rows_top = np.concatenate(top_rows) if top_rows else np.zeros(0, np.int64)
        index_top = np.concatenate(top_index) if top_index else np.zeros(0, np.int64)
        scored = rows_top >= 0

        def gather(values: np.ndarray, rows: np.ndarray) -> np.ndarray:
            out = np.zeros(rows.size)
            ok = rows >= 0
            out[ok] = np.asarray(values, dtype=np.float64)[rows[ok]]
            return out

        def top_values(rows: np.ndarray) -> dict[str, np.ndarray]:
            values = {f"fce_top{k}": gather(bench.fc_passed, rows)}
            for level in self.levels:
                values[f"gsr_top{k}_{level}"] = gather(p[level], rows)
            for level in self.levels:
                values[f"precision_at_{k}_{level}"] = gather(label[level], rows)
            return values

        metrics, per_family, per_object = breakdown(
            top_values(rows_top),
            index_top,
            ids,
            families,
            n_resamples=self.n_resamples,
            seed=self.seed,
        )
        family_of = [f or "(none)" for f in families]
        for level in self.levels:
            name = f"ap_{level}"
            objs = np.array(sorted(ap[level]), dtype=np.int64)
            values = np.array([ap[level][i] for i in objs], dtype=np.float64)
            metrics[name] = object_rate(values, objs, None, self.n_resamples, self.seed)
            for family, entry in per_family.items():
                in_family = np.array([family_of[i] == family for i in objs], dtype=bool)
                entry[name] = object_rate(values, objs, in_family, self.n_resamples, self.seed)
            for index, object_id in enumerate(ids):
                per_object[object_id][name] = ap[level].get(index)
        for index, object_id in enumerate(ids):
            entry = per_object[object_id]
            entry["candidates"] = int((bench.object_index == index).sum())
            entry["scored"] = object_id not in failures and entry["candidates"] > 0

        all_rows = np.concatenate(chance_rows) if chance_rows else np.zeros(0, np.int64)
        return self.result(
            benchmark=ref.record(),
            subject=code_subject(
                "classifier", subject, "torch.nn.Module" if module else "callable", sha256
            ),
            parameters=self.run_parameters(),
            seeds=self.run_seeds(),
            headline=self.headline,
            metrics=metrics,
            per_family=per_family,
            per_object=per_object,
            failures=failures,
            details={
                "objects": len(ids),
                "scored_objects": sum(1 for e in per_object.values() if e["scored"]),
                "failed_objects": len(failures),
                "top_k_rows": int(rows_top.size),
                "top_k_rows_of_failed_objects": int((~scored).sum()),
                "candidates": int(all_rows.size),
                "objects_without_positive": {
                    level: len(no_positive[level]) for level in self.levels
                },
                "objects_without_positive_ids": {
                    level: no_positive[level] for level in self.levels
                },
                "chance": self._chance(all_rows, p, label, ap),
            },
        )

    def _chance(
        self,
        rows: np.ndarray,
        p: dict[str, np.ndarray],
        label: dict[str, np.ndarray],
        ap: dict[str, dict[int, float]],
    ) -> dict[str, float | None]:
        """Expected metrics of a random ranking: means over objects of the object's mean."""
        bench = self.ref.benchmark
        groups = bench.object_index[rows]

        def per_object_mean(values: np.ndarray) -> float | None:
            if rows.size == 0:
                return None
            _, inverse = np.unique(groups, return_inverse=True)
            sums = np.bincount(inverse, weights=np.asarray(values, np.float64)[rows])
            return float(np.mean(sums / np.bincount(inverse)))

        out: dict[str, float | None] = {f"fce_top{self.k}": per_object_mean(bench.fc_passed)}
        for level in self.levels:
            out[f"gsr_top{self.k}_{level}"] = per_object_mean(p[level])
            out[f"precision_at_{self.k}_{level}"] = per_object_mean(label[level])
            fractions = [float(label[level][bench.object_index == i].mean()) for i in ap[level]]
            out[f"ap_{level}"] = float(np.mean(fractions)) if fractions else None
        return out
