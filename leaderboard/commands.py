"""``dg16m leaderboard ...``: a board on one machine from the command line, and the service.

The logic lives in :mod:`leaderboard.board` (store and queue), :mod:`leaderboard.worker`,
:mod:`leaderboard.views`, :mod:`leaderboard.page` and :mod:`leaderboard.app`; this module holds
only the command line. Heavy imports happen inside the handlers.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

from dg16m_core import arguments
from dg16m_core.cli import add_command
from dg16m_env.cli.evaluate import add_benchmark_arguments

DEFAULT_DB = Path("runs") / "leaderboard" / "board.db"

EXAMPLES = (
    "  dg16m leaderboard team add lab-a --db runs/board.db        # prints the token once\n"
    "  dg16m leaderboard submit runs/refs/force_closure.h5 --team lab-a --db runs/board.db\n"
    "  dg16m leaderboard show --db runs/board.db\n"
    "  dg16m leaderboard render --db runs/board.db --out runs/board-html\n"
    "  dg16m leaderboard serve --db runs/board.db --port 8000 &\n"
    "  dg16m leaderboard worker --db runs/board.db --workers 2 &\n"
)


def _db(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--db", type=Path, default=DEFAULT_DB, help=f"the board's database (default {DEFAULT_DB})"
    )


def _scoring(parser: argparse.ArgumentParser) -> None:
    arguments.add_parallel_arguments(parser, "local processes per scoring run")
    parser.add_argument(
        "--lease", type=float, default=60.0, metavar="S", help="a claim's lease (default 60 s)"
    )


def register(subparsers: Any) -> None:
    """Add ``dg16m leaderboard {init,team,submit,show,status,render,serve,worker}``."""
    board = add_command(
        subparsers,
        "leaderboard",
        "A leaderboard of submissions: store, command line, web service and page.",
        EXAMPLES,
        description=(
            "A board keeps teams, their submission files (stored by content hash) and the "
            "results of the registered evaluators, in SQLite (WAL). Use it on one machine "
            "from the command line (team add, submit, show, render), or run it as a service "
            "that teams upload to with a token (serve) and that workers score from a queue "
            "(worker; a job left by a dead worker is re-run)."
        ),
    )
    actions = board.add_subparsers(dest="leaderboard_command", metavar="ACTION", required=True)
    for add in (
        _add_init,
        _add_team,
        _add_submit,
        _add_show,
        _add_status,
        _add_render,
        _add_serve,
        _add_worker,
    ):
        add(actions)


def _add_init(actions: Any) -> None:
    """``dg16m leaderboard init``."""
    init = add_command(
        actions,
        "init",
        "Make a board for a benchmark (other commands make one with the defaults).",
        "  dg16m leaderboard init --db runs/board.db --evaluators fce,gsr\n"
        "  dg16m leaderboard init --db runs/mine.db --benchmark runs/bench/benchmark.h5\n",
    )
    _db(init)
    add_benchmark_arguments(init)
    init.add_argument("--evaluators", default="fce,gsr", help="default evaluators (fce,gsr)")
    init.add_argument("--title", default="dg16m leaderboard", help="the page's title")
    init.set_defaults(handler=_init)


def _add_team(actions: Any) -> None:
    """``dg16m leaderboard team {add,list,token}``."""
    team = add_command(
        actions,
        "team",
        "Add a team (its token is printed once), list teams, or give a team a new token.",
        "  dg16m leaderboard team add lab-a --db runs/board.db\n"
        "  dg16m leaderboard team list --db runs/board.db\n"
        "  dg16m leaderboard team token lab-a --db runs/board.db\n",
    )
    team_actions = team.add_subparsers(dest="team_command", metavar="ACTION", required=True)
    for name, help_text in (
        ("add", "Add a team; prints its token (only its hash is stored)."),
        ("list", "List the teams and their submission counts."),
        ("token", "Give a team a new token (the old one stops working)."),
    ):
        example = {"add": "lab-a --token-file lab-a.token", "list": "", "token": "lab-a"}[name]
        sub = add_command(
            team_actions,
            name,
            help_text,
            f"  dg16m leaderboard team {name} {example} --db runs/board.db\n".replace(
                "  --", " --"
            ),
        )
        if name != "list":
            sub.add_argument("name", help="the team's name")
        sub.add_argument(
            "--token-file",
            type=Path,
            default=None,
            help="write the token to this file (mode 0600) instead of printing it",
        )
        _db(sub)
        sub.set_defaults(handler=_team, team_action=name)


def _add_submit(actions: Any) -> None:
    """``dg16m leaderboard submit``."""
    submit = add_command(
        actions,
        "submit",
        "Validate, store and score a submission file (locally, or on a service with --url).",
        "  dg16m leaderboard submit runs/mine.h5 --team lab-a --db runs/board.db\n"
        "  dg16m leaderboard submit runs/mine.h5 --team lab-a --evaluators fce --queue-only\n"
        "  dg16m leaderboard submit runs/mine.h5 --url http://127.0.0.1:8000 "
        "--token-file lab-a.token --wait 600\n",
        description=(
            "Locally: the file is validated against the board's benchmark, stored by content "
            "hash and queued; then this process scores it (unless --queue-only, which leaves "
            "it to 'dg16m leaderboard worker'). With --url: the file is uploaded to a running "
            "service with the team's token."
        ),
    )
    submit.add_argument("file", type=Path, help="the submission file (.h5)")
    submit.add_argument("--team", default=None, help="the submitting team (local boards)")
    submit.add_argument("--evaluators", default=None, help="comma-separated (default: board's)")
    submit.add_argument("--label", default=None, help="name on the board (default: the file's)")
    submit.add_argument("--queue-only", action="store_true", help="queue it, do not score it")
    _db(submit)
    _scoring(submit)
    remote = submit.add_argument_group("a running service instead of a local board")
    remote.add_argument("--url", default=None, help="the service, e.g. http://127.0.0.1:8000")
    remote.add_argument(
        "--token-file", type=Path, default=None, help="file holding the team's token"
    )
    remote.add_argument(
        "--wait", type=float, default=0.0, metavar="S", help="wait up to S s for the score"
    )
    arguments.add_progress_argument(submit, "no progress bars while scoring locally")
    submit.set_defaults(handler=_submit)


def _add_show(actions: Any) -> None:
    """``dg16m leaderboard show``."""
    show = add_command(
        actions,
        "show",
        "Print the board: per track (mesh, cloud) and evaluator, scored submissions ranked "
        "within their track, with 95%% CIs.",
        "  dg16m leaderboard show --db runs/board.db\n"
        "  dg16m leaderboard show --db runs/board.db --track cloud\n"
        "  dg16m leaderboard show --db runs/board.db --evaluator gsr --limit 10 --json\n",
    )
    _db(show)
    show.add_argument("--evaluator", default=None, help="only this evaluator")
    show.add_argument(
        "--track",
        choices=("mesh", "cloud"),
        default=None,
        help="only this track (default: every track, each ranked apart)",
    )
    arguments.add_limit_argument(show, "rows per evaluator (default 20)", 20)
    show.add_argument("--json", action="store_true", help="print the board view as JSON")
    show.set_defaults(handler=_show)


def _add_status(actions: Any) -> None:
    """``dg16m leaderboard status``."""
    status = add_command(
        actions,
        "status",
        "The queue (queued and running jobs, stale leases), or one submission's events and log.",
        "  dg16m leaderboard status --db runs/board.db\n"
        "  dg16m leaderboard status 7 --db runs/board.db\n",
    )
    status.add_argument("submission", type=int, nargs="?", default=None)
    _db(status)
    status.set_defaults(handler=_status)


def _add_render(actions: Any) -> None:
    """``dg16m leaderboard render``."""
    render = add_command(
        actions,
        "render",
        "Write the board as static HTML (index.html, a page per submission, assets, JSON).",
        "  dg16m leaderboard render --db runs/board.db --out runs/board-html\n",
    )
    _db(render)
    arguments.add_out_argument(render, "the folder to write")
    render.set_defaults(handler=_render)


def _add_serve(actions: Any) -> None:
    """``dg16m leaderboard serve``."""
    serve = add_command(
        actions,
        "serve",
        "Run the HTTP service (teams upload with tokens; the page; JSON API).",
        "  dg16m leaderboard serve --db runs/board.db --host 127.0.0.1 --port 8000\n",
        description=(
            "An ASGI app (Starlette) under uvicorn. Scoring is done by separate processes: "
            "run 'dg16m leaderboard worker --db SAME' (one or more). Routes are listed in "
            "leaderboard.app; uploads are POST /api/submissions with 'Authorization: Bearer "
            "TOKEN' and the file as the body."
        ),
    )
    _db(serve)
    serve.add_argument("--host", default="127.0.0.1", help="address (default 127.0.0.1)")
    serve.add_argument("--port", type=int, default=8000, help="port (0: any free one)")
    serve.add_argument(
        "--max-upload-mb", type=float, default=64.0, help="largest upload (default 64 MiB)"
    )
    serve.add_argument(
        "--rate-limit", type=int, default=10, help="uploads per team per window (default 10)"
    )
    serve.add_argument(
        "--rate-window", type=float, default=3600.0, metavar="S", help="window (default 3600 s)"
    )
    serve.add_argument(
        "--header-timeout",
        type=float,
        default=10.0,
        metavar="S",
        help="time for a request's line and headers to arrive (default 10 s)",
    )
    serve.add_argument(
        "--body-timeout",
        type=float,
        default=30.0,
        metavar="S",
        help="longest pause within an upload's body (default 30 s; whole body: 600 s)",
    )
    serve.add_argument(
        "--shutdown-timeout",
        type=float,
        default=5.0,
        metavar="S",
        help="on SIGTERM, time for requests in flight before they are abandoned (default 5 s)",
    )
    serve.add_argument("--log-level", default="warning", help="uvicorn's log level")
    serve.set_defaults(handler=_serve)


def _add_worker(actions: Any) -> None:
    """``dg16m leaderboard worker``."""
    worker = add_command(
        actions,
        "worker",
        "Score queued submissions (run several; a job left by a dead worker is re-run).",
        "  dg16m leaderboard worker --db runs/board.db --workers 2\n"
        "  dg16m leaderboard worker --db runs/board.db --backend ray --address auto\n"
        "  dg16m leaderboard worker --db runs/board.db --idle-exit 30   # stop when idle\n",
        description=(
            "Claims the oldest queued job with a lease (renewed while it scores), scores it "
            "with the submission's evaluators and stores the results. SIGTERM or Ctrl-C: "
            "finish the current job, then stop. A worker killed outright leaves its lease to "
            "expire; the next claim re-queues the job."
        ),
    )
    _db(worker)
    _scoring(worker)
    worker.add_argument("--poll", type=float, default=1.0, metavar="S", help="idle wait (1 s)")
    worker.add_argument("--max-jobs", type=int, default=None, help="stop after N jobs")
    worker.add_argument(
        "--idle-exit", type=float, default=None, metavar="S", help="stop after S s idle"
    )
    worker.set_defaults(handler=_worker)


def _open(args: argparse.Namespace, *, create: bool = False) -> Any:
    from .board import Board

    return Board(args.db, create=create)


def _init(args: argparse.Namespace) -> int:
    from .board import Board, BoardError, check_evaluators

    if args.db.exists():
        raise BoardError(f"--db: expected a new file, found {args.db} (a board exists there)")
    board = Board(
        args.db,
        benchmark=args.benchmark,
        mesh_root=args.mesh_root,
        evaluators=check_evaluators(args.evaluators),
        title=args.title,
    )
    setting = board.benchmark
    print(
        f"made {args.db}: benchmark {setting.sha256[:12]} ({len(setting.object_ids)} objects), "
        f"evaluators {','.join(board.evaluators)}"
    )
    return 0


def _check_token_file(path: Path | None) -> None:
    """Refuse an existing ``--token-file`` before a token is made (it would be lost)."""
    from .board import BoardError

    if path is not None and (path.exists() or path.is_symlink()):
        raise BoardError(f"--token-file: expected a new file, found {path}")


def _team(args: argparse.Namespace) -> int:
    from .tokens import write_token_file

    action = args.team_action
    board = _open(args, create=action == "add")
    if action == "list":
        counts: dict[str, int] = {}
        for row in board.submissions():
            counts[row["team"]] = counts.get(row["team"], 0) + 1
        from .worker import iso_time

        for team in board.teams():
            since = iso_time(team.created_at)
            print(f"{team.name:<24} {counts.get(team.name, 0):>4} submissions  since {since}")
        return 0
    _check_token_file(args.token_file)
    if action == "add":
        _, token = board.add_team(args.name)
    else:
        token = board.rotate_token(args.name)
    if args.token_file is not None:
        write_token_file(args.token_file, token)
        print(f"team {args.name}: token written to {args.token_file} (keep it secret)")
    else:
        print(f"team {args.name}: token (shown once, keep it secret):\n{token}")
    return 0


def _read_token(path: Path | None) -> str:
    from .board import BoardError

    token = os.environ.get("DG16M_TOKEN", "") if path is None else ""
    if path is not None:
        try:
            token = path.read_text(encoding="utf-8").strip()
        except OSError as exc:
            raise BoardError(f"--token-file: expected a readable file, found {exc}") from None
    if not token:
        raise BoardError(
            "--url: expected the team's token in --token-file or $DG16M_TOKEN, found none"
        )
    return token


def _submit(args: argparse.Namespace) -> int:
    from .board import BoardError

    if args.url is not None:
        from . import client

        token = _read_token(args.token_file)
        answer = client.upload(
            args.url, token, args.file, label=args.label, evaluators=args.evaluators
        )
        sid = int(answer["submission"])
        print(f"submission #{sid} queued on {args.url}", flush=True)
        if args.wait > 0:
            answer = client.wait(
                args.url, token, sid, timeout_s=args.wait, on_update=_print_progress(sid)
            )
            _print_submission(answer)
            return 0 if answer.get("status") == "scored" else 1
        return 0
    if args.team is None:
        raise BoardError("--team: expected the submitting team (or --url for a service)")
    from .worker import WorkerOptions, score_claim, worker_name

    board = _open(args, create=True)
    team = board.team(args.team)
    sid = board.submit(team, args.file, label=args.label, evaluators=args.evaluators)
    print(f"submission #{sid} stored and queued ({args.file.name})", flush=True)
    if args.queue_only:
        return 0
    options = WorkerOptions(
        lease_s=args.lease,
        **arguments.parallel_options(args),
        progress=not args.no_progress,
    )
    claim = board.claim(worker_name(), options.lease_s, submission_id=sid)
    if claim is None:
        print(f"submission #{sid} was claimed by a worker meanwhile")
        return 0
    print(f"submission #{sid}: scoring here with {args.workers} worker(s)", flush=True)
    outcome = score_claim(board, claim, options, on_log=lambda line: print(f"  {line}", flush=True))
    from .views import submission_view

    _print_submission(submission_view(board, sid, private=True))
    return 0 if outcome == "scored" else 1


def _plural(n: int, noun: str) -> str:
    return f"{n} {noun}" + ("" if n == 1 else "s")


def _print_progress(sid: int) -> Callable[[dict[str, Any], float], None]:
    """While ``--wait`` polls a service: a line when the status changes, and every 30 s."""
    last: dict[str, Any] = {"status": None, "at": -1e9}

    def show(answer: dict[str, Any], waited_s: float) -> None:
        status = answer.get("status")
        if status != last["status"] or waited_s - last["at"] >= 30.0:
            print(f"submission #{sid}: {status} ({waited_s:.0f} s)", flush=True)
            last.update(status=status, at=waited_s)

    return show


def _print_submission(view: dict[str, Any]) -> None:
    from dg16m_env.evaluators import EvaluationResult

    from .tracks import provenance_summary

    track = view.get("track") or "mesh"  # a service from before tracks sends none
    print(f"#{view['id']} {view['label']} ({view['team']}): {view['status']}, {track} track")
    if view.get("provenance") is not None and track != "mesh":
        print(f"  self-declared: {provenance_summary(view['provenance'])}")
    for result in view.get("results", {}).values():
        print("  " + EvaluationResult.from_dict(result).format().replace("\n", "\n  "))
    if view.get("error"):
        print(f"  error: {view['error']}")


def _show(args: argparse.Namespace) -> int:
    from dg16m_env.evaluators.result import format_rate

    from .board import BoardError
    from .tracks import provenance_summary
    from .views import board_view

    board = _open(args)
    view = board_view(board, track=args.track)
    sections = view["evaluators"]
    if args.evaluator is not None:
        sections = [s for s in sections if s["name"] == args.evaluator]
        if not sections:
            known = ", ".join(s["name"] for s in view["evaluators"])
            raise BoardError(f"--evaluator: expected one of {known}, found {args.evaluator!r}")
    if args.json:
        print(json.dumps({**view, "evaluators": sections}, indent=1))
        return 0
    bench = view["benchmark"]
    counts = view["counts"]
    print(
        f"{view['title']}: benchmark {bench['sha256'][:12]} ({bench['objects']} objects); "
        f"{_plural(counts['teams'], 'team')}, {_plural(counts['submissions'], 'submission')} "
        f"({counts['scored']} "
        f"scored, {counts['queued']} queued, {counts['running']} running, {counts['failed']} "
        "failed)"
    )
    titles = {t["name"]: t["title"] for t in view["tracks"]}
    track = None
    for section in sections:
        if section["track"] != track:
            track = section["track"]
            print(f"\n== {titles[track]}")
        print(f"\n{section['name']} (ranked by {section['headline']}) in the {track} track")
        if not section["rows"]:
            print("  no scored submissions yet")
            continue
        columns = section["columns"][:3]
        header = f"  {'rank':>4}  {'team':<16} {'submission':<36}" + "".join(
            f" {c:<24}" for c in columns
        )
        print(header + " date")
        for row in section["rows"][: args.limit]:
            cells = "".join(
                f" {format_rate(row['metrics'].get(c)).split(' (')[0]:<24}" for c in columns
            )
            name = f"{row['label'][:30]} #{row['submission']}"
            print(f"  {row['rank']:>4}  {row['team'][:16]:<16} {name:<36}{cells} {row['date']}")
            if track != "mesh" and row.get("provenance") is not None:
                print(f"        self-declared: {provenance_summary(row['provenance'])}")
        if len(section["rows"]) > args.limit:
            print(f"  ... {len(section['rows']) - args.limit} more (--limit)")
    return 0


def _status(args: argparse.Namespace) -> int:
    from .views import queue_view, submission_view

    board = _open(args)
    if args.submission is not None:
        view = submission_view(board, args.submission, private=True)
        _print_submission(view)
        print("  events:")
        for event in view["events"]:
            worker = f" [{event['worker']}]" if event["worker"] else ""
            print(f"    {event['at']} {event['state']:<8}{worker} {event['message']}")
        if view["log"]:
            print("  log:")
            print("    " + view["log"].rstrip("\n").replace("\n", "\n    "))
        return 0
    view = queue_view(board)
    counts = view["counts"]
    print(
        f"{counts['queued']} queued, {counts['running']} running, {counts['scored']} scored, "
        f"{counts['failed']} failed"
    )
    for job in view["jobs"]:
        lease = ""
        if job["state"] == "running":
            lease = f" lease until {job['lease_expires_at']} by {job['worker']}"
            if job["stale"]:
                lease += " (STALE: the worker stopped renewing; the next claim re-queues it)"
        print(
            f"  #{job['submission']} {job['team']}/{job['label']}: {job['state']}, "
            f"attempt {job['attempts']}{lease}"
        )
    return 0


def _render(args: argparse.Namespace) -> int:
    from .page import write_static
    from .views import board_view, submission_view

    board = _open(args)
    view = board_view(board)
    ids = sorted({row["submission"] for s in view["evaluators"] for row in s["rows"]})
    out = write_static(args.out, view, {i: submission_view(board, i) for i in ids})
    print(f"wrote {out / 'index.html'} and {len(ids)} submission pages")
    return 0


def _serve(args: argparse.Namespace) -> int:
    from .app import MIB, ServiceConfig, serve

    board = _open(args)
    config = ServiceConfig(
        max_upload_bytes=int(args.max_upload_mb * MIB),
        rate_limit=args.rate_limit,
        rate_window_s=args.rate_window,
        header_timeout_s=args.header_timeout,
        body_idle_timeout_s=args.body_timeout,
        shutdown_timeout_s=args.shutdown_timeout,
    )
    serve(
        board,
        host=args.host,
        port=args.port,
        config=config,
        log_level=args.log_level,
        ready=lambda url: print(f"serving {args.db} on {url}", flush=True),
    )
    return 0


def _worker(args: argparse.Namespace) -> int:
    from .worker import WorkerOptions, run_worker, worker_name

    board = _open(args)
    options = WorkerOptions(
        lease_s=args.lease,
        poll_s=args.poll,
        **arguments.parallel_options(args),
        max_jobs=args.max_jobs,
        idle_exit_s=args.idle_exit,
    )
    stop = threading.Event()

    def graceful(signum: int, frame: Any) -> None:
        print("stopping after the current job", flush=True)
        stop.set()

    signal.signal(signal.SIGTERM, graceful)
    name = worker_name()
    print(f"worker {name} on {args.db}", flush=True)
    done = run_worker(board, options, name=name, stop=stop, report=lambda m: print(m, flush=True))
    print(f"worker {name}: {done} jobs", flush=True)
    return 0
