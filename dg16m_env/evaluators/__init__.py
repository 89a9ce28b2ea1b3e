"""Registered evaluators: score submissions, classifiers and policies the same way, reproducibly.

``make(name, **kwargs)`` builds an evaluator, ``names()`` lists them, ``register(name)`` adds one
(see :mod:`dg16m_env.evaluators.registry`). Built-ins (each module's docstring says what it
measures and which arguments it takes):

* ``fce`` (:mod:`.fce`): force-closure efficiency of a submission's dual grasps;
* ``gsr`` (:mod:`.gsr`): grasp success rate in simulation (benchmark protocol v2);
* ``classifier`` (:mod:`.classifier`): top-k FCE / GSR, AP and precision@k of a classifier's
  ranking of the benchmark's candidates (the paper's Table II protocol);
* ``policy`` (:mod:`.policy`): success rate of a policy over seeded episodes of an environment.

Layer rule: modules here import the subjects, benchmark and physics layers below them, never the
envs or cli above (the ``policy`` evaluator makes environments by id, through Gymnasium).

Every result (:class:`EvaluationResult`) records the evaluator's version, the package version,
the benchmark's sha256 and every seed.
"""

# The built-ins register themselves on import.
from dg16m_env.benchmark.ref import BenchmarkRef, load_benchmark_ref

from . import classifier, fce, gsr, policy
from .registry import Evaluator, EvaluatorError, evaluator_class, make, names, register
from .result import EvaluationResult, ResultError, breakdown, read_results, write_results
from .submissions import submission_evaluators

__all__ = [  # the built-in modules are listed: importing them registers them
    "BenchmarkRef",
    "EvaluationResult",
    "Evaluator",
    "EvaluatorError",
    "ResultError",
    "breakdown",
    "classifier",
    "evaluator_class",
    "fce",
    "gsr",
    "load_benchmark_ref",
    "make",
    "names",
    "policy",
    "read_results",
    "register",
    "submission_evaluators",
    "write_results",
]
