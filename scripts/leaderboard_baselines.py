"""Put the reference submissions on a leaderboard, so that the board is never empty.

    python scripts/leaderboard_baselines.py --db runs/leaderboard/board.db --workers 2

For the board's benchmark, writes the reference submissions of ``dg16m baselines submissions``
(random, farthest and force-closure pairing, the paper's Table III, and the benchmark's own
passing pairs) next to the database, and with ``--predictors`` the submission of each
``module:callable`` predictor (run locally with the predictor runner's default time and memory
limits, e.g. the point-cloud predictors of :mod:`baselines.cloud_predictor`), adds the team
``baselines`` when it is missing (its token goes to ``baselines.token`` beside the database, mode
0600), then submits each file and scores it in this process (or only queues it with
``--queue-only``, for running workers). A file the team already submitted is skipped, so running
the script again is harmless.

    python scripts/leaderboard_baselines.py --db runs/leaderboard/board.db --strategies "" \
        --predictors baselines.cloud_predictor:cgdf_predictor,baselines.cloud_predictor:cgdf_robust_predictor

The cloud track (predictors see only the benchmark's depth cameras, ranked apart):

    python scripts/leaderboard_baselines.py --db runs/leaderboard/board.db --strategies "" \
        --track cloud --predictors baselines.flow_predictor:flow_predictor
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from baselines.reference_submissions import parse_strategies, write_reference_submissions
from baselines.submission_arguments import DEFAULT_STRATEGIES
from dg16m_env.subjects.predictor import submission_from_predictor
from dg16m_env.subjects.predictor_process import PredictorSpec
from leaderboard.board import (
    DEFAULT_EVALUATORS,
    Board,
    DuplicateError,
    NotFoundError,
    check_evaluators,
)
from leaderboard.tokens import write_token_file
from leaderboard.worker import WorkerOptions, score_claim, worker_name

TEAM = "baselines"


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--db", type=Path, default=Path("runs/leaderboard/board.db"))
    parser.add_argument("--benchmark", type=Path, default=None, help="a new board's benchmark")
    parser.add_argument(
        "--evaluators", default=None, help="default: the board's (a new board's: fce,gsr)"
    )
    parser.add_argument(
        "--strategies",
        default=",".join(DEFAULT_STRATEGIES),
        help=f"reference pairing strategies, comma-separated, or '' for none "
        f"(default {','.join(DEFAULT_STRATEGIES)})",
    )
    parser.add_argument(
        "--predictors",
        default="",
        help="module:callable predictors to submit too, comma-separated (default none)",
    )
    parser.add_argument(
        "--track",
        default="mesh",
        choices=("mesh", "cloud"),
        help="what the predictors see: the mesh (default) or only the benchmark's depth cameras",
    )
    parser.add_argument("--k", type=int, default=10, help="dual grasps per object (10)")
    parser.add_argument(
        "--seed",
        type=int,
        default=0,
        help="seed of the reference strategies and of the predictors' observations (0)",
    )
    parser.add_argument("--workers", type=int, default=1, help="local processes")
    parser.add_argument("--queue-only", action="store_true", help="queue; leave scoring to workers")
    parser.add_argument("--no-progress", action="store_true")
    return parser.parse_args(argv)


def baselines_team(board: Board, db: Path) -> object:
    """The team ``baselines``, added (with its token saved beside the database) if missing."""
    try:
        return board.team(TEAM)
    except NotFoundError:
        team, token = board.add_team(TEAM)
        path = db.parent / f"{TEAM}.token"
        write_token_file(path, token, overwrite=True)
        print(f"added team {TEAM} (token in {path})")
        return team


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    evaluators = check_evaluators(args.evaluators) if args.evaluators else DEFAULT_EVALUATORS
    board = Board(args.db, benchmark=args.benchmark, evaluators=evaluators)
    ref = board.benchmark_ref()
    out = args.db.parent / "reference"
    paths: dict[str, Path] = {}
    if args.strategies.strip():
        started = time.perf_counter()
        paths = write_reference_submissions(
            out,
            benchmark=ref,
            mesh_root=ref.mesh_root,
            k=args.k,
            seed=args.seed,
            workers=args.workers,
            strategies=parse_strategies(args.strategies),
            progress=not args.no_progress,
        )
        took = time.perf_counter() - started
        print(f"wrote {len(paths)} reference submissions to {out} in {took:.0f} s")
    out.mkdir(parents=True, exist_ok=True)
    for target in [t.strip() for t in args.predictors.split(",") if t.strip()]:
        name = target.rsplit(":", 1)[-1] + ("" if args.track == "mesh" else f"-{args.track}")
        started = time.perf_counter()
        path, run = submission_from_predictor(
            PredictorSpec(target=target),
            out / f"{name}.h5",
            benchmark=ref,
            seed=args.seed,  # the observations' point clouds
            max_grasps=args.k,
            track=args.track,
            progress=not args.no_progress,
        )
        took = time.perf_counter() - started
        failed_on = f", failed on {len(run.errors)} objects" if run.errors else ""
        print(f"{name}: wrote {path} in {took:.0f} s{failed_on}")
        paths[name] = path
    team = baselines_team(board, args.db)
    options = WorkerOptions(workers=args.workers)
    failed = 0
    for name, path in paths.items():
        try:
            sid = board.submit(team, path, label=f"baseline: {name}", evaluators=args.evaluators)
        except DuplicateError as exc:
            print(f"{name}: already on the board as #{exc.submission_id}, skipped")
            continue
        if args.queue_only:
            print(f"{name}: queued as #{sid}")
            continue
        claim = board.claim(worker_name(), options.lease_s, submission_id=sid)
        if claim is None:
            print(f"{name}: #{sid} was claimed by a running worker")
            continue
        outcome = score_claim(board, claim, options)
        failed += outcome != "scored"
        scores = {e: r["metrics"][r["headline"]]["rate"] for e, r in board.results(sid).items()}
        shown = ", ".join(f"{e} {100 * v:.1f}%" for e, v in scores.items() if v is not None)
        print(f"{name}: #{sid} {outcome} {shown}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
