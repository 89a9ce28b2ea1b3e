"""``dg16m evaluate`` and ``dg16m submission {validate,make}``: the registered evaluators on the
command line. The logic lives in :mod:`dg16m_env.evaluators`, :mod:`dg16m_env.subjects.submission` and
:mod:`dg16m_env.subjects.predictor`; heavy imports happen inside the handlers."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from dataset_gen.cli import add_command
from dataset_gen.errors import Dg16mError
from dg16m_env.physics.simulator import add_simulator_arguments, simulator_from_args

EVALUATE_EXAMPLES = (
    "  # score a submission file: force-closure efficiency and simulated success\n"
    "  dg16m evaluate runs/refs/force_closure.h5 --evaluators fce,gsr --workers 2 "
    "--out runs/fc.json\n"
    "  # run your predictor (a function observation -> dual grasps) in a sandboxed process\n"
    "  dg16m evaluate --predictor my_grasps.py:predict --save-submission runs/mine.h5\n"
    "  # rank the benchmark's candidates with a classifier (the paper's Table II protocol)\n"
    "  dg16m evaluate --classifier my_classifier.py:score --k 10\n"
    "  # a policy on a registered Gymnasium environment, 100 seeded episodes\n"
    "  dg16m evaluate --policy my_policy.py:act --env-id dg16m_env/DualGraspSelect-v0\n"
    "  dg16m evaluate --list\n"
)

SUBMISSION_EXAMPLES = (
    "  dg16m submission validate runs/mine.h5\n"
    "  dg16m submission make --from-dg16m runs/generated/grasps --out runs/gen.h5 --k 10\n"
    "  dg16m submission make --predictor my_grasps.py:predict --out runs/mine.h5\n"
)


class EvaluateCommandError(Dg16mError, ValueError):
    """Bad ``dg16m evaluate`` / ``dg16m submission`` arguments."""


def benchmark_argument(text: str) -> Path:
    """``--benchmark``'s value: a short name (``procedural``, ``real``) resolved to its shipped
    file, or a path."""
    from dg16m_env.benchmark.model import BenchmarkError
    from dg16m_env.benchmark.names import benchmark_file

    try:
        return benchmark_file(text)
    except BenchmarkError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_benchmark_arguments(parser: argparse.ArgumentParser) -> None:
    """``--benchmark`` and ``--mesh-root``: the benchmark a command works on (also used by the
    commands of the packages above, e.g. ``dg16m baselines submissions``)."""
    parser.add_argument(
        "--benchmark",
        type=benchmark_argument,
        default=None,
        help="benchmark file, or a shipped benchmark by name: 'procedural' (the default) or "
        "'real' (300 real furniture objects)",
    )
    parser.add_argument(
        "--mesh-root", type=Path, default=None, help="folder of a mesh benchmark's meshes"
    )


def _predictor_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--time-limit",
        type=float,
        default=60.0,
        metavar="S",
        help="seconds the predictor may take per object (default 60)",
    )
    parser.add_argument(
        "--memory-limit",
        type=int,
        default=4096,
        metavar="MB",
        help="address-space limit of the predictor's process (default 4096 MB)",
    )
    parser.add_argument(
        "--max-grasps", type=int, default=100, help="dual grasps per object at most (default 100)"
    )
    parser.add_argument(
        "--points", type=int, default=2048, help="points in each observation (default 2048)"
    )


def register(subparsers: Any) -> None:
    """Add ``dg16m evaluate`` and ``dg16m submission {validate,make}``."""
    ev = add_command(
        subparsers,
        "evaluate",
        "Score a submission, a predictor, a classifier or a policy with registered evaluators.",
        EVALUATE_EXAMPLES,
        description=(
            "Runs registered evaluators (dg16m_env.evaluators) on one subject. A submission "
            "file (or a predictor's output) is validated in full before anything is scored; "
            "fce closes each hand's jaws on the object and checks force closure; gsr labels "
            "each dual grasp by its success probability over the nominal and K perturbed "
            "MuJoCo trials. Rates count every submitted grasp (invalid = 0, an object that "
            "cannot be simulated = 0) and carry object-resampled 95% confidence intervals. "
            "Each result records the evaluator's version, the package version, the benchmark's "
            "sha256 and every seed; the same inputs give the same result."
        ),
    )
    ev.add_argument("submission", type=Path, nargs="?", default=None, help="submission file (.h5)")
    ev.add_argument(
        "--evaluators",
        default=None,
        help="comma-separated names (default: fce,gsr for submissions and predictors, "
        "classifier with --classifier, policy with --policy)",
    )
    subject = ev.add_argument_group("other subjects (instead of a submission file)")
    subject.add_argument(
        "--predictor",
        metavar="MODULE:CALLABLE",
        help="a function observation -> dual grasps, run in a child process with limits",
    )
    subject.add_argument(
        "--classifier",
        metavar="MODULE:ATTR",
        help="a callable (observation, poses) -> scores or a torch module (trusted, in process)",
    )
    subject.add_argument(
        "--policy",
        metavar="MODULE:ATTR",
        help="a callable observation -> action or an SB3 model (trusted, in process)",
    )
    add_benchmark_arguments(ev)
    ev.add_argument("--out", type=Path, default=None, help="write the results as JSON here")
    ev.add_argument("--workers", type=int, default=1, help="local processes (default 1)")
    ev.add_argument("--backend", choices=("local", "ray"), default="local")
    ev.add_argument("--address", default=None, help="Ray address: auto or host:port")
    ev.add_argument(
        "--perturbations",
        type=int,
        default=None,
        metavar="K",
        help="gsr: perturbed trials per grasp (default: the benchmark's, 8)",
    )
    ev.add_argument("--seed", type=int, default=0, help="seed of the confidence intervals")
    ev.add_argument("--k", type=int, default=10, help="classifier: top-k per object (default 10)")
    ev.add_argument("--env-id", default=None, help="policy: a registered Gymnasium id")
    ev.add_argument("--episodes", type=int, default=100, help="policy: episodes (default 100)")
    ev.add_argument(
        "--save-submission",
        type=Path,
        default=None,
        help="predictor: where to write the submission file it produces (default: beside "
        "--out, OUT's name with .submission.h5; without --out runs/predictor_submission.h5)",
    )
    _predictor_options(ev)
    add_simulator_arguments(ev)
    ev.add_argument("--list", action="store_true", help="list the registered evaluators and exit")
    ev.add_argument("--no-progress", action="store_true", help="no progress bars")
    ev.set_defaults(handler=_evaluate)

    sub = add_command(
        subparsers,
        "submission",
        "Validate a submission file, or make one from DG16M files or a predictor.",
        SUBMISSION_EXAMPLES,
        description="Submission files hold each benchmark object's dual grasps (HDF5, schema "
        "in dg16m_env.subjects.submission).",
    )
    actions = sub.add_subparsers(dest="submission_command", metavar="ACTION", required=True)
    validate = add_command(
        actions,
        "validate",
        "Check a submission file against the benchmark; list every problem with its place.",
        "  dg16m submission validate runs/mine.h5\n",
    )
    validate.add_argument("file", type=Path)
    add_benchmark_arguments(validate)
    validate.set_defaults(handler=_validate)

    make = add_command(
        actions,
        "make",
        "Write a submission from DG16M grasp files or from a predictor.",
        SUBMISSION_EXAMPLES,
        description="--from-dg16m takes up to K force-closure-passing pairs of each object's "
        "DG16M file (<id>.h5, e.g. the output of 'dg16m generate'), filled with failing ones; "
        "--predictor runs a function observation -> dual grasps in a child process with time "
        "and memory limits (an object where it fails gets a grasp that cannot succeed, and "
        "the failure is recorded in the file's metadata).",
    )
    source = make.add_mutually_exclusive_group(required=True)
    source.add_argument("--from-dg16m", type=Path, metavar="DIR", help="folder of <id>.h5 files")
    source.add_argument("--predictor", metavar="MODULE:CALLABLE")
    make.add_argument("--out", type=Path, required=True, help="the submission file to write")
    make.add_argument("--k", type=int, default=10, help="--from-dg16m: pairs per object")
    make.add_argument("--seed", type=int, default=0, help="--from-dg16m: seed of the choice")
    make.add_argument(
        "--grasp-gripper",
        default=None,
        help="--from-dg16m: gripper frame of the files' poses (default: the file's own, else "
        "robotiq_2f85 as in the DG16M release)",
    )
    add_benchmark_arguments(make)
    _predictor_options(make)
    make.add_argument("--no-progress", action="store_true", help="no progress bar")
    make.set_defaults(handler=_make)


def _names(text: str | None, default: str) -> list[str]:
    names = [n.strip() for n in (text or default).split(",") if n.strip()]
    if not names:
        raise EvaluateCommandError(f"--evaluators: expected names like fce,gsr, found {text!r}")
    return names


def _evaluate(args: argparse.Namespace) -> int:
    from dg16m_env import evaluators
    from dg16m_env.evaluators import (
        load_benchmark_ref,
        make,
        submission_evaluators,
        write_results,
    )

    if args.list:
        for name in evaluators.names():
            cls = evaluators.evaluator_class(name)
            print(f"{name:<12} v{cls.version:<4} scores a {cls.subject_kind}")
        return 0
    subjects = [
        s
        for s in ("submission", "predictor", "classifier", "policy")
        if getattr(args, s) is not None
    ]
    if len(subjects) != 1:
        raise EvaluateCommandError(
            "expected one subject: a submission file, --predictor, --classifier or --policy; "
            f"found {len(subjects)} ({', '.join(subjects) or 'none'})"
        )
    kind = subjects[0]
    simulator = simulator_from_args(args)
    if not simulator.is_default and kind in ("classifier", "policy"):
        raise EvaluateCommandError(
            f"--simulator {simulator.name}: expected a submission or --predictor (the gsr "
            f"evaluator runs trials), found --{kind}"
        )
    progress = not args.no_progress
    started = time.perf_counter()
    results: dict[str, Any] = {}
    record: dict[str, Any] = {"kind": kind}
    if kind == "policy":
        if args.env_id is None:
            raise EvaluateCommandError("--policy: expected --env-id, found none")
        policy = _load_trusted(args.policy)
        for name in _names(args.evaluators, "policy"):
            ev = make(name, env_id=args.env_id, n_episodes=args.episodes, seed=args.seed)
            results[name] = ev.evaluate(policy)
        record["target"] = args.policy
    else:
        ref = load_benchmark_ref(args.benchmark, args.mesh_root)
        if kind == "classifier":
            classifier = _load_trusted(args.classifier)
            for name in _names(args.evaluators, "classifier"):
                ev = make(name, benchmark=ref, k=args.k, seed=args.seed, progress=progress)
                results[name] = ev.evaluate(classifier)
            record["target"] = args.classifier
        else:
            submission = _submission_subject(args, ref, kind, progress)
            record.update({"file": str(submission), "target": args.predictor})
            built = submission_evaluators(
                _names(args.evaluators, "fce,gsr"),
                ref,
                workers=args.workers,
                backend=args.backend,
                address=args.address,
                seed=args.seed,
                n_perturbations=args.perturbations,
                progress=progress,
                simulator=simulator,
            )
            results = {name: ev.evaluate(submission) for name, ev in built.items()}
    for result in results.values():
        print(result.format())
    print(f"scored in {time.perf_counter() - started:.1f} s")
    if args.out is not None:
        write_results(args.out, results, record)
        print(f"wrote {args.out}")
    return 0


def _predictor_spec(args: argparse.Namespace) -> Any:
    from dg16m_env.subjects.predictor_process import PredictorSpec

    return PredictorSpec(
        target=args.predictor,
        time_limit_s=args.time_limit,
        memory_limit_mb=args.memory_limit,
    )


def predictor_submission_path(results: Path | None) -> Path:
    """Where ``evaluate --predictor`` writes the submission it produces unless told: beside the
    results file (``a/b.json`` -> ``a/b.submission.h5``), so two evaluations with different
    ``--out`` never write the same file; without ``--out``, ``runs/predictor_submission.h5``."""
    if results is None:
        return Path("runs") / "predictor_submission.h5"
    return results.with_name(f"{results.stem}.submission.h5")


def _submission_subject(args: argparse.Namespace, ref: Any, kind: str, progress: bool) -> Path:
    """The submission file to score: the given one, or the one the predictor produced."""
    if kind == "submission":
        return args.submission
    from dg16m_env.subjects.predictor import submission_from_predictor

    out = args.save_submission or predictor_submission_path(args.out)
    path, run = submission_from_predictor(
        _predictor_spec(args),
        out,
        benchmark=ref,
        n_points=args.points,
        max_grasps=args.max_grasps,
        progress=progress,
    )
    _print_predictor_errors(run.errors)
    print(f"wrote {path}")
    return path


def _print_predictor_errors(errors: dict[str, str]) -> None:
    if errors:
        print(f"the predictor failed on {len(errors)} objects (their grasps count as 0):")
        for object_id, message in sorted(errors.items())[:10]:
            print(f"  {object_id}: {message.splitlines()[-1] if message else ''}")


def _load_trusted(target: str) -> Any:
    """The object ``module:attr`` names (imported in this process: your own trusted code); a
    class is instantiated without arguments."""
    from dg16m_env.subjects.predictor_process import load_target

    value = load_target(target)
    return value() if isinstance(value, type) else value


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}" + ("" if n == 1 else "s")


def _validate(args: argparse.Namespace) -> int:
    from dataset_gen.io import open_hdf5
    from dg16m_env.evaluators import load_benchmark_ref
    from dg16m_env.subjects.submission_reader import validate_submission

    # a file that cannot be read is bad input (exit 2); what opens is checked (problems: exit 1)
    with open_hdf5(args.file, "HDF5 submission file"):
        pass
    ref = load_benchmark_ref(args.benchmark, args.mesh_root)
    problems = validate_submission(
        args.file, object_ids=ref.object_ids, benchmark_sha256=ref.sha256, embedded=ref.embedded
    )
    if problems:
        print(f"{args.file}: {_count(len(problems), 'problem')}")
        for problem in problems:
            print(f"  {problem}")
        return 1
    print(f"{args.file}: valid for the benchmark {ref.sha256[:12]} ({len(ref.object_ids)} objects)")
    return 0


def _make(args: argparse.Namespace) -> int:
    from dg16m_env.evaluators import load_benchmark_ref
    from dg16m_env.subjects.submission import EMBEDDED
    from dg16m_env.subjects.submission_writer import submission_from_dg16m, write_submission

    ref = load_benchmark_ref(args.benchmark, args.mesh_root)
    if args.predictor is not None:
        from dg16m_env.subjects.predictor import submission_from_predictor

        path, run = submission_from_predictor(
            _predictor_spec(args),
            args.out,
            benchmark=ref,
            n_points=args.points,
            max_grasps=args.max_grasps,
            progress=not args.no_progress,
        )
        _print_predictor_errors(run.errors)
    else:
        poses, scores = submission_from_dg16m(
            args.from_dg16m, ref.object_ids, k=args.k, seed=args.seed, gripper=args.grasp_gripper
        )
        path = write_submission(
            args.out,
            poses,
            scores=scores,
            benchmark=EMBEDDED if ref.embedded else ref.sha256,
            metadata={"source": "dg16m files", "folder": str(args.from_dg16m), "k": args.k},
        )
    print(f"wrote {path}")
    return 0
