"""``dg16m evaluate`` and ``dg16m submission {validate,make}``: the registered evaluators on the
command line. The logic lives in :mod:`dg16m_env.evaluators`, :mod:`dg16m_env.subjects.submission` and
:mod:`dg16m_env.subjects.predictor`; heavy imports happen inside the handlers."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

from dg16m_core import arguments
from dg16m_core.cli import add_command
from dg16m_core.errors import Dg16mError
from dg16m_core.stopping import sigterm_interrupts
from dg16m_env.cli import tracks
from dg16m_env.physics.simulator import add_simulator_arguments, simulator_from_args

EVALUATE_EXAMPLES = (
    "  # score a submission file: force-closure efficiency and simulated success\n"
    "  dg16m evaluate runs/refs/force_closure.h5 --evaluators fce,gsr --workers 2 "
    "--out runs/fc.json\n"
    "  # a quick look: 5 objects of the real benchmark (the result says it is partial)\n"
    "  dg16m evaluate --predictor baselines.pairing_baselines:force_closure_baseline "
    "--evaluators fce,gsr --benchmark real --limit 5\n"
    "  # after Ctrl-C or SIGTERM: finished evaluators were kept in --out, and gsr's finished\n"
    "  # objects beside it (runs/fc.gsr.checkpoint/); skip them all (classifier and\n"
    "  # policy runs resume the same way)\n"
    "  dg16m evaluate runs/refs/force_closure.h5 --out runs/fc.json --resume\n"
    "  # run your predictor (a function observation -> dual grasps) in a sandboxed process\n"
    "  dg16m evaluate --predictor my_grasps.py:predict --save-submission runs/mine.h5\n"
    "  # the cloud track: it sees only two noisy depth cameras, never the mesh\n"
    "  dg16m evaluate --predictor baselines.cloud_predictor:cgdf_partial_predictor "
    "--track cloud --out runs/cloud.json\n"
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


def add_subset_arguments(parser: argparse.ArgumentParser) -> None:
    """``--objects`` and ``--limit``: score a few of the benchmark's objects (a partial run)."""
    group = parser.add_mutually_exclusive_group()
    group.add_argument(
        "--objects",
        metavar="IDS",
        default=None,
        help="only these objects: comma-separated ids, or a file with one id a line; the "
        "submission must hold exactly them (evaluate --policy: episodes draw only among them, e.g. "
        "the held-out objects) and the result is marked partial (never ranked)",
    )
    arguments.add_limit_argument(
        group, "only the benchmark's first N objects (a partial run, as --objects)", metavar="N"
    )


def subset_of(ref: Any, args: argparse.Namespace) -> Any:
    """``ref`` restricted to ``--objects`` / ``--limit`` (unchanged without them).

    Raises:
        BenchmarkError: unknown or repeated ids, ``--limit`` < 1.
    """
    from dg16m_env.benchmark.ref import parse_object_ids

    if getattr(args, "objects", None) is not None:
        return ref.subset(parse_object_ids(args.objects))
    if getattr(args, "limit", None) is not None:
        return ref.first(args.limit)
    return ref


def partial_note(ref: Any) -> str:
    """One line saying a run scores only some of the benchmark's objects."""
    return (
        f"partial run: {len(ref.object_ids)} of the benchmark's {ref.full_objects} objects "
        "(results are marked partial; the leaderboard never ranks them)"
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
    tracks.add_track_arguments(parser)


def register(subparsers: Any) -> None:
    """Add ``dg16m evaluate`` and ``dg16m submission {validate,make}``."""
    _register_evaluate(subparsers)
    _register_submission(subparsers)


def _register_evaluate(subparsers: Any) -> None:
    """Add ``dg16m evaluate``."""
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
    _evaluate_arguments(ev)
    ev.set_defaults(handler=_evaluate)


def _evaluate_arguments(ev: argparse.ArgumentParser) -> None:
    """The options of ``dg16m evaluate``."""
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
    add_subset_arguments(ev)
    ev.add_argument(
        "--out",
        type=Path,
        default=None,
        help="write the results as JSON here (rewritten atomically as each evaluator finishes, "
        "so Ctrl-C keeps the finished ones)",
    )
    ev.add_argument(
        "--resume",
        action="store_true",
        help="keep the results --out already holds for the same subject (a file's sha256, or "
        "for --classifier / --policy the sha256 of its module's source and its torch weights), "
        "benchmark (sha256 and objects), seeds, parameters and evaluator and package versions, "
        "and run only the others; gsr, classifier and policy continue from the objects (or "
        "episodes) their checkpoint beside --out (OUT.NAME.checkpoint/) holds, with the same "
        "result as an uninterrupted run (a --predictor run also reuses the submission it "
        "wrote)",
    )
    arguments.add_parallel_arguments(ev, "local processes (default 1)")
    ev.add_argument(
        "--perturbations",
        type=int,
        default=None,
        metavar="K",
        help="gsr: perturbed trials per grasp (default: the benchmark's, 8)",
    )
    arguments.add_seed_argument(ev, "seed of the confidence intervals")
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
    arguments.add_progress_argument(ev, "no progress bars")


def _register_submission(subparsers: Any) -> None:
    """Add ``dg16m submission {validate,make}``."""
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
    add_subset_arguments(validate)
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
    arguments.add_out_argument(make, "the submission file to write")
    make.add_argument("--k", type=int, default=10, help="--from-dg16m: pairs per object")
    arguments.add_seed_argument(make, "--from-dg16m: seed of the choice")
    make.add_argument(
        "--grasp-gripper",
        default=None,
        help="--from-dg16m: gripper frame of the files' poses (default: the file's own, else "
        "robotiq_2f85 as in the DG16M release)",
    )
    add_benchmark_arguments(make)
    _predictor_options(make)
    arguments.add_progress_argument(make)
    make.set_defaults(handler=_make)


def _names(text: str | None, default: str) -> list[str]:
    names = [n.strip() for n in (text or default).split(",") if n.strip()]
    if not names:
        raise EvaluateCommandError(f"--evaluators: expected names like fce,gsr, found {text!r}")
    return names


def _evaluate(args: argparse.Namespace) -> int:
    from dg16m_env import evaluators

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
    if args.resume and args.out is None:
        raise EvaluateCommandError("--resume: expected --out RESULTS.json to resume, found none")
    if args.track != "mesh" and kind != "predictor":
        raise EvaluateCommandError(
            f"--track {args.track}: expected --predictor (a submission file declares its own "
            f"track in its metadata), found {'a submission file' if kind == 'submission' else '--' + kind}"
        )
    if kind == "policy" and args.env_id is None:
        raise EvaluateCommandError("--policy: expected --env-id, found none")
    if kind == "submission":  # a file that cannot be read is bad input, before anything else
        from dataset_gen.io import open_hdf5

        with open_hdf5(args.submission, "HDF5 submission file"):
            pass
    progress = not args.no_progress
    started = time.perf_counter()
    record: dict[str, Any] = {"kind": kind}
    state = _RunState(out=args.out, kind=kind)
    with sigterm_interrupts():  # SIGTERM stops the run as Ctrl-C does (exit 130)
        try:
            results = _run_subject(args, kind, record, simulator, progress, state)
        except KeyboardInterrupt:
            print(state.interrupted(), file=sys.stderr)
            raise
    for result in results.values():
        print(result.format())
    print(f"scored in {time.perf_counter() - started:.1f} s")
    if record.get("partial"):
        objects = record["objects"]
        print(
            f"PARTIAL: {len(objects['subset'])} of {objects['of']} objects; not comparable with "
            "full results, and the leaderboard refuses it"
        )
    if args.out is not None:
        _save(args.out, results, record)
        print(f"wrote {args.out}")
    return 0


def _run_subject(
    args: argparse.Namespace,
    kind: str,
    record: dict[str, Any],
    simulator: Any,
    progress: bool,
    state: _RunState,
) -> dict[str, Any]:
    """Run the evaluators on the subject of kind ``kind``; ``state`` follows the stages."""
    from dg16m_env.evaluators import load_benchmark_ref, make

    results = state.results
    subset = args.objects is not None or args.limit is not None
    ref = None
    if kind != "policy" or subset:
        ref = subset_of(load_benchmark_ref(args.benchmark, args.mesh_root), args)
        if ref.partial:
            record.update(
                {"partial": True, "objects": {"subset": ref.object_ids, "of": ref.full_objects}}
            )
            print(partial_note(ref))
    if kind == "policy":
        env_kwargs = _policy_env_kwargs(args, ref)
        built = {
            name: make(
                name,
                env_id=args.env_id,
                n_episodes=args.episodes,
                seed=args.seed,
                env_kwargs=env_kwargs,
                progress=progress,
            )
            for name in _names(args.evaluators, "policy")
        }
        _score_code(args, args.policy, built, record, state)
    elif kind == "classifier":
        built = {
            name: make(name, benchmark=ref, k=args.k, seed=args.seed, progress=progress)
            for name in _names(args.evaluators, "classifier")
        }
        _score_code(args, args.classifier, built, record, state)
    else:
        _score_submission(args, ref, kind, record, simulator, progress, state)
    return results


def _score_code(
    args: argparse.Namespace,
    target: str,
    built: dict[str, Any],
    record: dict[str, Any],
    state: _RunState,
) -> None:
    """Score the classifier or policy ``target`` names (``module:attr``, trusted code run in
    this process) with each evaluator of ``built``; it is told apart in checkpoints and
    ``--resume`` by the sha256 of its code and weights."""
    from dg16m_env.evaluators.code_identity import code_sha256

    subject = _load_trusted(target)
    sha256 = code_sha256(subject)
    record.update({"target": target, "sha256": sha256})
    stored = _stored(args.out)[1] if args.resume else {}
    _run_evaluators(args, built, subject, sha256, record, state, stored)


def _policy_env_kwargs(args: argparse.Namespace, ref: Any) -> dict[str, Any] | None:
    """``--policy``'s environment options: with ``--objects`` / ``--limit``, episodes draw only
    among those objects of the benchmark (e.g. the held-out ones), passed as the environment's
    ``object_ids`` (and ``benchmark`` when ``--benchmark`` names one)."""
    if ref is None or not ref.partial:
        return None
    kwargs: dict[str, Any] = {"object_ids": list(ref.object_ids)}
    if args.benchmark is not None:
        kwargs["benchmark"] = str(args.benchmark)
    return kwargs


class _RunState:
    """Where a ``dg16m evaluate`` run is, so that an interrupt (Ctrl-C, SIGTERM) can say what
    was kept and how to go on."""

    def __init__(self, out: Path | None, kind: str) -> None:
        self.out, self.kind = out, kind
        self.stage = "predictor" if kind == "predictor" else "setup"
        self.results: dict[str, Any] = {}
        self.checkpoint: Path | None = None
        self.submission: Path | None = None  # a predictor's submission, recorded in --out

    def interrupted(self) -> str:
        """One line: the stage that was stopped, what was kept, how to go on."""
        if self.stage == "predictor":
            where = (
                "interrupted while the predictor ran (its submission is written once every "
                "object is done)"
            )
        else:
            where = f"interrupted during {self.stage}"
        if self.out is None:
            return (
                f"{where}: nothing was kept (no --out); rerun with --out RESULTS.json to be able "
                "to --resume"
            )
        kept = []
        if self.submission is not None:
            kept.append(f"kept the predictor's submission {self.submission}")
        if self.results:
            kept.append(f"kept {', '.join(self.results)} in {self.out}")
        n = len(list(self.checkpoint.glob("[0-9]*.npz"))) if self.checkpoint else 0
        if n:
            units = "episodes" if self.kind == "policy" else "objects"
            kept.append(f"kept {n} finished {self.stage} {units} in {self.checkpoint}")
        kept_text = "; ".join(kept)
        if not kept:
            return f"{where}: nothing was kept; rerun the command to start again"
        return f"{where}: {kept_text}; rerun with --resume to continue from there"


def _save(out: Path | None, results: dict[str, Any], record: dict[str, Any]) -> None:
    """Write what is finished so far (atomically), so that an interrupt keeps it."""
    if out is not None:
        from dg16m_env.evaluators import write_results

        write_results(out, results, record)


def _stored(out: Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """``--resume``: the subject record and results ``out`` holds (nothing when it is absent)."""
    from dg16m_env.evaluators.result import read_results_file

    if not out.exists():
        print(
            f"--resume: no finished evaluators in {out} (no such file): running every evaluator "
            "(one with a checkpoint beside it goes on from there)"
        )
        return {}, {}
    return read_results_file(out)


def _score_submission(
    args: argparse.Namespace,
    ref: Any,
    kind: str,
    record: dict[str, Any],
    simulator: Any,
    progress: bool,
    state: _RunState,
) -> dict[str, Any]:
    """Score a submission file (given, or made by ``--predictor``) with each evaluator, writing
    ``--out`` after each (and, for an evaluator that checkpoints, each finished object beside
    it); with ``--resume``, results ``--out`` already holds for the same run are kept and not
    scored again, and a checkpointed evaluator goes on from its finished objects."""
    from dg16m_core.hashing import file_sha256
    from dg16m_env.evaluators import submission_evaluators

    stored_subject, stored = _stored(args.out) if args.resume else ({}, {})
    reused = _reusable_submission(args, ref, stored_subject) if kind == "predictor" else None
    if reused is not None:
        submission, sha256 = reused
    else:
        state.stage = "predictor" if kind == "predictor" else "setup"
        submission = _submission_subject(args, ref, kind, progress)
        sha256 = file_sha256(submission)
    state.stage = "setup"
    record.update({"file": str(submission), "target": args.predictor, "sha256": sha256})
    record["track"] = tracks.file_track(submission)
    built = submission_evaluators(
        _names(args.evaluators, "fce,gsr"),
        ref,
        **arguments.parallel_options(args),
        seed=args.seed,
        n_perturbations=args.perturbations,
        progress=progress,
        simulator=simulator,
    )
    if kind == "predictor" and args.out is not None:  # recorded in --out for a resume
        state.submission = submission
    return _run_evaluators(args, built, submission, sha256, record, state, stored)


def _run_evaluators(
    args: argparse.Namespace,
    built: dict[str, Any],
    subject: Any,
    sha256: str,
    record: dict[str, Any],
    state: _RunState,
    stored: dict[str, Any],
) -> dict[str, Any]:
    """Score ``subject`` (whose identity is ``sha256``) with each evaluator of ``built``,
    writing ``--out`` after each (and, for an evaluator that checkpoints, each finished object
    beside it); with ``--resume``, the results ``stored`` in ``--out`` for the same run are
    kept and not scored again, and a checkpointed evaluator goes on from its finished
    objects."""
    results = state.results
    for name, ev in built.items():
        if name in stored:
            _check_resumable(args.out, name, stored[name], ev.planned(), sha256)
            results[name] = stored[name]
            print(f"{name}: kept from {args.out} (finished in an earlier run; --resume)")
            # stopped between writing the result and removing its checkpoint: remove it now
            _remove_checkpoint(args.out, name)
    if results or state.submission is not None:  # a predictor's submission is recorded too
        _save(args.out, results, record)
    for name, ev in built.items():
        if name in results:
            continue
        state.stage = name
        options: dict[str, Any] = {}
        if args.out is not None and _checkpoints(ev):
            from dg16m_env.evaluators.checkpoint import CheckpointRequest, checkpoint_folder

            state.checkpoint = checkpoint_folder(args.out, name)
            options["checkpoint"] = CheckpointRequest(
                state.checkpoint, resume=args.resume, remove=False
            )
        results[name] = ev.evaluate(subject, **options)
        _save(args.out, results, record)
        if state.checkpoint is not None:  # the result is written: its checkpoint is done
            _remove_checkpoint(args.out, name)
            state.checkpoint = None
    return results


def _remove_checkpoint(out: Path, name: str) -> None:
    """Remove ``name``'s checkpoint beside ``out`` (its result is in ``out``)."""
    import shutil

    from dg16m_env.evaluators.checkpoint import checkpoint_folder

    shutil.rmtree(checkpoint_folder(out, name), ignore_errors=True)


def _checkpoints(ev: Any) -> bool:
    """Whether the evaluator ``ev`` checkpoints per object (its ``evaluate`` takes
    ``checkpoint=``)."""
    import inspect

    return "checkpoint" in inspect.signature(ev.evaluate).parameters


def _check_resumable(
    out: Path, name: str, result: Any, planned: dict[str, Any] | None, sha256: str
) -> None:
    """Refuse to keep a stored result of another run (another subject, benchmark, subset,
    seeds, parameters or versions): mixing runs in one file would be a wrong result."""
    from dg16m_core.json_values import json_ready

    stored = result.to_dict()
    found = stored.get("subject", {}).get("sha256")
    differences = (
        [] if found == sha256 else [f"subject sha256 {str(found)[:12]} (expected {sha256[:12]})"]
    )
    if planned is None:
        differences.append("an evaluator that cannot tell its run before scoring")
    else:
        for key, value in json_ready(planned).items():
            if stored.get(key) != value:
                differences.append(f"another {key}")
    if differences:
        raise EvaluateCommandError(
            f"--resume: expected {out}'s {name} result to be of this run, found "
            f"{'; '.join(differences)}; remove the file or choose another --out"
        )


def _reusable_submission(
    args: argparse.Namespace, ref: Any, stored_subject: dict[str, Any]
) -> tuple[Path, str] | None:
    """``--resume`` of a ``--predictor`` run: the submission the earlier run wrote and its
    sha256, when it was made by the same predictor for the same objects and is unchanged."""
    from dg16m_core.hashing import file_sha256

    file, sha256 = stored_subject.get("file"), stored_subject.get("sha256")
    if not (isinstance(file, str) and isinstance(sha256, str)):
        return None
    wanted = args.save_submission or predictor_submission_path(args.out)
    objects = stored_subject.get("objects")
    same_objects = (objects or None) == (
        {"subset": ref.object_ids, "of": ref.full_objects} if ref.partial else None
    )
    path = Path(file)
    if (
        stored_subject.get("target") != args.predictor
        or not same_objects
        or path.resolve() != Path(wanted).resolve()
        or not path.is_file()
        or file_sha256(path) != sha256
        or not tracks.same_track(args, path)
    ):
        return None
    print(f"--resume: reusing the predictor's submission {path} (sha256 {sha256[:12]})")
    return path, sha256


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
    cloud = tracks.cloud_track(args)
    path, run = submission_from_predictor(
        _predictor_spec(args),
        out,
        benchmark=ref,
        n_points=args.points,
        max_grasps=args.max_grasps,
        progress=progress,
        track=args.track,
        cloud=cloud,
    )
    tracks.print_sandbox(run, cloud)
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
    ref = subset_of(load_benchmark_ref(args.benchmark, args.mesh_root), args)
    if ref.partial:
        print(partial_note(ref))
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

        cloud = tracks.cloud_track(args)
        path, run = submission_from_predictor(
            _predictor_spec(args),
            args.out,
            benchmark=ref,
            n_points=args.points,
            max_grasps=args.max_grasps,
            progress=not args.no_progress,
            track=args.track,
            cloud=cloud,
        )
        tracks.print_sandbox(run, cloud)
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
