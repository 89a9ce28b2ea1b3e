"""The shared command-line options of :mod:`dg16m_core.arguments`."""

from __future__ import annotations

import argparse
from pathlib import Path

from dg16m_core import arguments


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser()
    arguments.add_out_argument(parser, "output folder")
    arguments.add_parallel_arguments(parser)
    arguments.add_seed_argument(parser)
    arguments.add_limit_argument(parser, "at most N", metavar="N")
    arguments.add_progress_argument(parser)
    return parser


def test_defaults_and_values() -> None:
    args = _parser().parse_args(["--out", "x"])
    assert args.out == Path("x")
    assert (args.workers, args.backend, args.address, args.seed, args.limit) == (
        1,
        "local",
        None,
        0,
        None,
    )
    assert args.no_progress is False
    argv = "--out y --workers 3 --backend ray --address auto --seed 5 --limit 2 --no-progress"
    args = _parser().parse_args(argv.split())
    assert arguments.parallel_options(args) == {"workers": 3, "backend": "ray", "address": "auto"}
    assert (args.seed, args.limit, args.no_progress) == (5, 2, True)


def test_local_only_parallel_arguments() -> None:
    parser = argparse.ArgumentParser()
    arguments.add_parallel_arguments(parser, "processes (default: 1)", ray=False)
    assert vars(parser.parse_args([])) == {"workers": 1}


def test_optional_out() -> None:
    parser = argparse.ArgumentParser()
    arguments.add_out_argument(parser, "folder", required=False)
    assert parser.parse_args([]).out is None


def test_listed_ids(tmp_path: Path) -> None:
    assert arguments.listed_ids(" a, b,,c ") == ["a", "b", "c"]
    assert arguments.listed_ids(" , ") == []
    file = tmp_path / "ids.txt"
    file.write_text("a  # first\n\n# a comment\nb\n", encoding="utf-8")
    assert arguments.listed_ids(str(file), file) == ["a", "b"]
