"""Predictors as code: limits, failures per object, restarts, and the submission they make."""

from __future__ import annotations

import json
import multiprocessing
import os
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

from dg16m_env.subjects.predictor import (
    FAILED_PLACEHOLDER,
    PredictorRun,
    _metadata_errors,
    run_predictor,
    submission_from_predictor,
)
from dg16m_env.subjects.predictor_process import PredictorError, PredictorSpec, load_target
from dg16m_env.subjects.submission_reader import validate_submission

PREDICTORS = '''
import os
import time

import numpy as np


def poses(obs, k=3):
    """(k, 2, 4, 4) rigid hand poses around the cloud's centre, a function of the observation."""
    centre = np.asarray(obs["points"], dtype=np.float64).mean(axis=0)
    p = np.tile(np.eye(4), (k, 2, 1, 1))
    p[:, 0, :3, 3] = centre + (0.1, 0.0, 0.0)
    p[:, 1, :3, 3] = centre - (0.1, 0.0, 0.0)
    p[:, :, 2, 3] += 0.01 * np.arange(k)[:, None]
    return p


def array(obs):
    return poses(obs)


def pair(obs):
    p = poses(obs)
    return p, np.linspace(1.0, 0.0, len(p))


def mapping(obs):
    return {"poses": poses(obs).astype(np.float32), "scores": [3, 2, 1]}


def integers(obs):
    return np.tile(np.eye(4, dtype=np.int64), (2, 2, 1, 1))


def wrong_shape(obs):
    return np.zeros((3, 4, 4))


def nan(obs):
    p = poses(obs)
    p[0, 1, 0, 3] = np.nan
    return p


def nan_scores(obs):
    return poses(obs), np.array([1.0, np.inf, 0.0])


def not_rigid(obs):
    p = poses(obs)
    p[1, 0, :3, :3] *= 2.0
    return p


def far(obs):
    p = poses(obs)
    p[0, :, 0, 3] = 20.0
    return p


def many(obs):
    return poses(obs, k=5)


def text(obs):
    return "grasps"


def raises(obs):
    if obs["object_id"] == "a":
        raise ValueError("no grasp for object a")
    return poses(obs)


def hangs(obs):
    if obs["object_id"] == "b":
        time.sleep(100)
    return poses(obs)


def slow(obs):
    time.sleep(0.3)  # longer than a progress bar's refresh interval
    return poses(obs)


def crashes(obs):
    if obs["object_id"] == "b":
        os._exit(3)
    return poses(obs)


LIMIT_MB = 1024


def hog(obs):
    if obs["object_id"] == "b":
        bytearray(2 * LIMIT_MB * 1024 * 1024)
    return poses(obs)


def start_method(obs):
    import multiprocessing

    raise ValueError(f"start method {multiprocessing.get_start_method()}")


def benchmark(obs):
    if obs["object_id"].startswith("crate"):
        raise RuntimeError("crates are hard")
    return pair(obs)


NOT_CALLABLE = 3
'''


@pytest.fixture(scope="module")
def module_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The predictors above, as a file."""
    path = tmp_path_factory.mktemp("predictors") / "my_predictors.py"
    path.write_text(textwrap.dedent(PREDICTORS))
    return path


def spec(module_file: Path, name: str, **kwargs: Any) -> PredictorSpec:
    """A spec for one predictor of the file, with limits small enough for tests."""
    kwargs = {"time_limit_s": 2.0, "memory_limit_mb": 1024, "startup_time_limit_s": 20.0} | kwargs
    return PredictorSpec(f"{module_file}:{name}", **kwargs)


def observations(ids: str = "abc") -> list[dict[str, Any]]:
    """Small synthetic observations (8 points each), one per letter."""
    out = []
    for k, object_id in enumerate(ids):
        rng = np.random.default_rng(k)
        out.append(
            {
                "object_id": object_id,
                "family": "box",
                "points": rng.random((8, 3)).astype(np.float32),
                "normals": np.tile(np.float32([0, 0, 1]), (8, 1)),
            }
        )
    return out


def assert_succeeded(run: PredictorRun, ids: str, k: int = 3) -> None:
    for object_id in ids:
        assert object_id not in run.errors, run.errors
        assert run.poses[object_id].shape == (k, 2, 4, 4)
        assert run.poses[object_id].dtype == np.float64


@pytest.fixture(autouse=True)
def no_leftovers(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Any:
    """Every test: temporary files under a folder of its own, and after it no temporary folder,
    no child process left."""
    temp = tmp_path / "tmp"
    temp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temp))
    yield
    assert list(temp.iterdir()) == []
    assert multiprocessing.active_children() == []


def test_array(module_file: Path) -> None:
    obs = observations()
    run = run_predictor(spec(module_file, "array"), obs)
    assert_succeeded(run, "abc")
    assert run.errors == {}
    assert run.scores == {}
    assert run.restarts == 0
    assert run.object_ids == ["a", "b", "c"]
    centre = obs[1]["points"].astype(np.float64).mean(axis=0)
    np.testing.assert_allclose(run.poses["b"][0, 0, :3, 3], centre + np.array([0.1, 0, 0]))
    summary = json.loads(json.dumps(run.summary()))
    assert (summary["succeeded"], summary["failed"], summary["dual_grasps"]) == (3, 0, 9)


def test_pair_mapping_and_integers(module_file: Path) -> None:
    run = run_predictor(spec(module_file, "pair"), observations("ab"))
    assert_succeeded(run, "ab")
    np.testing.assert_array_equal(run.scores["a"], [1.0, 0.5, 0.0])
    run = run_predictor(spec(module_file, "mapping"), observations("ab"))
    assert_succeeded(run, "ab")
    assert run.scores["b"].dtype == np.float64
    np.testing.assert_array_equal(run.scores["b"], [3.0, 2.0, 1.0])
    run = run_predictor(spec(module_file, "integers"), observations("a"))
    np.testing.assert_array_equal(run.poses["a"], np.tile(np.eye(4), (2, 2, 1, 1)))


@pytest.mark.parametrize(
    ("name", "message"),
    [
        ("wrong_shape", "poses: expected shape (K, 2, 4, 4), found (3, 4, 4)"),
        ("nan", "poses: expected finite values, found 1 NaN or inf entries"),
        ("nan_scores", "scores: expected finite values, found 1 NaN or inf entries"),
        ("not_rigid", "poses: expected a rotation (|R^T R - I| < 0.0001), found a scaled"),
        ("far", "poses: expected hands within 10 m of the object origin, found a translation"),
        ("many", "poses: expected 1 to 4 dual grasps, found 5"),
        (
            "text",
            "expected an array (K, 2, 4, 4), a (poses, scores) tuple or a dict, found str",
        ),
    ],
)
def test_invalid_returns(module_file: Path, name: str, message: str) -> None:
    run = run_predictor(spec(module_file, name), observations("ab"), max_grasps=4)
    assert run.poses == {}
    assert run.restarts == 0
    assert set(run.errors) == {"a", "b"}
    assert run.errors["a"].startswith(message), run.errors["a"]


def test_exception_is_reported_and_the_run_goes_on(module_file: Path) -> None:
    run = run_predictor(spec(module_file, "raises"), observations())
    assert set(run.errors) == {"a"}
    error = run.errors["a"]
    assert error.splitlines()[-1] == "ValueError: no grasp for object a"
    assert 'raise ValueError("no grasp for object a")' in error  # the traceback's tail
    assert len(error.splitlines()) <= 6
    assert_succeeded(run, "bc")
    assert run.restarts == 0


def test_timeout_kills_and_restarts(module_file: Path) -> None:
    run = run_predictor(spec(module_file, "hangs", time_limit_s=1.5), observations("abcd"))
    assert run.errors == {"b": "timed out after 1.5 s"}
    assert_succeeded(run, "acd")
    assert run.restarts == 1
    # The hung call was cut at its limit, not left to run its 100 s (a generous bound: no
    # speed is measured here).
    assert 1.5 <= run.seconds["b"] < 60.0


def test_crash_is_reported_and_restarts(module_file: Path) -> None:
    run = run_predictor(spec(module_file, "crashes"), observations("abcd"))
    assert run.errors == {"b": "the predictor process died (exit code 3)"}
    assert_succeeded(run, "acd")
    assert run.restarts == 1


def test_the_child_uses_the_parents_start_method(module_file: Path) -> None:
    """multiprocessing's bootstrap makes "spawn" a spawned child's default: the predictor's own
    locks (tqdm's) were then named semaphores of the parent's resource tracker."""
    run = run_predictor(spec(module_file, "start_method"), observations("a"))
    found = run.errors["a"].splitlines()[-1]
    assert found == f"ValueError: start method {multiprocessing.get_start_method()}"


SLEEPER = """
import multiprocessing
import time
from pathlib import Path

from tqdm import tqdm


def predict(observation):
    tqdm.get_lock()  # tqdm's lock: a semaphore of the default start method
    lock = multiprocessing.get_context("spawn").Lock()  # a named one, in the resource tracker
    Path(MARK).touch()
    time.sleep(600)
    return lock
"""

# Python's own SIGINT handler, as in a terminal (a background job starts with SIGINT ignored)
CLI_MAIN = (
    "import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
    "from dg16m_core.cli import main; sys.exit(main(sys.argv[1:]))"
)


def test_ctrl_c_during_a_call_exits_130_without_leaks(tmp_path: Path) -> None:
    """Ctrl-C (SIGINT to the terminal's process group) while the predictor sleeps in a call:
    exit status 130 and no "leaked semaphore" warning from the resource tracker."""
    mark = tmp_path / "started"
    module = tmp_path / "sleeper.py"
    module.write_text(SLEEPER.replace("MARK", repr(str(mark))))
    argv = ["evaluate", "--predictor", f"{module}:predict", "--limit", "1", "--evaluators", "fce"]
    argv += ["--save-submission", str(tmp_path / "s.h5"), "--out", str(tmp_path / "r.json")]
    argv += ["--time-limit", "600", "--no-progress"]
    process = subprocess.Popen(
        [sys.executable, "-c", CLI_MAIN, *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # its own process group, as a terminal's foreground job
    )
    try:
        deadline = time.monotonic() + 120  # the import and the first observation
        while not mark.exists() and process.poll() is None and time.monotonic() < deadline:
            time.sleep(0.1)
        assert mark.exists(), f"expected the predictor to start, found rc {process.poll()}"
        os.killpg(process.pid, signal.SIGINT)
        _, err = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.communicate()
    assert process.returncode == 130, err
    assert "interrupted" in err
    assert "leaked" not in err, err
    assert "Traceback" not in err, err


def test_memory_limit(module_file: Path) -> None:
    run = run_predictor(spec(module_file, "hog", memory_limit_mb=1024), observations("abc"))
    assert set(run.errors) == {"b"}
    assert "MemoryError" in run.errors["b"]
    assert "1024 MB" in run.errors["b"]
    assert_succeeded(run, "ac")


def test_memory_limit_under_the_baseline(module_file: Path) -> None:
    with pytest.raises(PredictorError, match="memory_limit_mb: expected more than"):
        run_predictor(spec(module_file, "array", memory_limit_mb=16), observations("a"))


@pytest.mark.parametrize(
    ("target", "message"),
    [
        ("no_such_module_dg16m:predict", "expected an importable module 'no_such_module_dg16m'"),
        ("{file}:missing", "to have an attribute 'missing', found none"),
        ("{file}:NOT_CALLABLE", "expected a callable, found int"),
        ("{folder}/absent.py:predict", "expected a Python file at"),
    ],
)
def test_import_errors(module_file: Path, target: str, message: str) -> None:
    target = target.format(file=module_file, folder=module_file.parent)
    with pytest.raises(PredictorError, match="failed to start") as info:
        run_predictor(PredictorSpec(target, startup_time_limit_s=20.0), observations("a"))
    assert message in str(info.value)


def test_import_exception_and_import_timeout(tmp_path: Path) -> None:
    broken = tmp_path / "broken.py"
    broken.write_text("import numpy\n\nraise RuntimeError('no weights found')\n")
    with pytest.raises(PredictorError, match="failed to start") as info:
        run_predictor(PredictorSpec(f"{broken}:predict"), observations("a"))
    assert str(info.value).splitlines()[-1] == "RuntimeError: no weights found"
    assert "broken.py" in str(info.value)  # the traceback's tail
    slow = tmp_path / "slow.py"
    slow.write_text("import time\n\ntime.sleep(100)\n")
    with pytest.raises(PredictorError, match="the import timed out after 1 s"):
        run_predictor(PredictorSpec(f"{slow}:predict", startup_time_limit_s=1.0), observations("a"))


def test_restart_that_fails(tmp_path: Path) -> None:
    once = tmp_path / "once.py"
    once.write_text(
        textwrap.dedent(
            f"""
            import os
            from pathlib import Path

            import numpy as np

            MARK = Path({str(tmp_path / "imported")!r})
            if MARK.exists():
                raise ImportError("second import")
            MARK.touch()


            def predict(obs):
                if obs["object_id"] == "b":
                    os._exit(5)
                return np.eye(4)[None, None].repeat(2, axis=1)
            """
        )
    )
    run = run_predictor(PredictorSpec(f"{once}:predict", time_limit_s=2.0), observations("abcd"))
    assert run.poses["a"].shape == (1, 2, 4, 4)
    assert run.errors["b"] == "the predictor process died (exit code 5)"
    for object_id in "cd":
        assert run.errors[object_id] == (
            "not run: the predictor could not be restarted: ImportError: second import"
        )
    assert run.restarts == 0


def test_failing_observations_clean_up(module_file: Path) -> None:
    def failing() -> Any:
        yield from observations("a")
        raise KeyError("observation b")

    with pytest.raises(KeyError, match="observation b"):
        run_predictor(spec(module_file, "array"), failing())


def test_module_target_with_path(module_file: Path) -> None:
    target = PredictorSpec(
        "my_predictors:pair", path=(str(module_file.parent),), startup_time_limit_s=20.0
    )
    run = run_predictor(target, observations("a"))
    assert_succeeded(run, "a")
    with pytest.raises(PredictorError, match="attribute 'nope'"):
        load_target("my_predictors:nope", path=[str(module_file.parent)])


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"target": "no_colon"}, "target: expected 'package.module:callable'"),
        ({"target": "a.b:"}, "target: expected"),
        ({"target": "a-b:f"}, "found the module 'a-b'"),
        ({"target": "m:f", "time_limit_s": 0}, "time_limit_s: expected seconds > 0, found 0"),
        ({"target": "m:f", "memory_limit_mb": -1}, "memory_limit_mb: expected an integer >= 0"),
        ({"target": "m:f", "path": "folder"}, "path: expected a sequence of folders"),
    ],
)
def test_spec_validation(kwargs: dict[str, Any], message: str) -> None:
    with pytest.raises(PredictorError) as info:
        PredictorSpec(**kwargs)
    assert message in str(info.value)


def test_bad_observations(module_file: Path) -> None:
    with pytest.raises(PredictorError, match="unique object ids, found 'a' twice"):
        run_predictor(spec(module_file, "array"), observations("aa"))


def test_deterministic(module_file: Path) -> None:
    first = run_predictor(spec(module_file, "pair"), observations())
    second = run_predictor(spec(module_file, "pair"), observations())
    for object_id in "abc":
        np.testing.assert_array_equal(first.poses[object_id], second.poses[object_id])
        np.testing.assert_array_equal(first.scores[object_id], second.scores[object_id])


def test_metadata_errors_are_shortened() -> None:
    errors = {f"object-{k}": "x\n" + "y" * 500 for k in range(1000)}
    short = _metadata_errors(errors)
    assert len(json.dumps(short)) < 60_000
    assert all(v.endswith("...") and v.startswith("y") for v in short.values())


def test_submission_from_predictor(module_file: Path, tmp_path: Path) -> None:
    from dg16m_env.benchmark.file import write_benchmark
    from dg16m_env.evaluators import load_benchmark_ref

    embedded = load_benchmark_ref()
    ids = [i for i in embedded.object_ids if i.startswith(("table", "crate", "chair"))][:3]
    assert any(i.startswith("crate") for i in ids)
    bench_path = tmp_path / "small.h5"
    write_benchmark(bench_path, embedded.benchmark.select_objects(ids))
    ref = load_benchmark_ref(bench_path)

    out = tmp_path / "runs" / "sub.h5"
    path, run = submission_from_predictor(
        spec(module_file, "benchmark"), out, benchmark=ref, n_points=64, seed=3, progress=False
    )
    assert path == out
    crate = next(i for i in ids if i.startswith("crate"))
    assert set(run.errors) == {crate}
    with h5py.File(out, "r") as f:
        assert f.attrs["benchmark"] == ref.sha256
        meta = json.loads(f.attrs["metadata"])
        assert sorted(f["objects"]) == sorted(ids)
        # the failed object weighs as much as an answered one (3 grasps each): 3 failures
        placeholders = f[f"objects/{crate}/poses"][()]
        assert placeholders.shape == (3, 2, 4, 4)
        np.testing.assert_array_equal(placeholders, np.repeat(FAILED_PLACEHOLDER, 3, axis=0))
        assert f"objects/{crate}/scores" not in f
        for object_id in set(ids) - {crate}:
            np.testing.assert_array_equal(f[f"objects/{object_id}/poses"][()], run.poses[object_id])
            np.testing.assert_array_equal(f[f"objects/{object_id}/scores"][()], [1.0, 0.5, 0.0])
    assert meta["predictor"] == f"{module_file}:benchmark"
    assert meta["failed_objects"] == {crate: "RuntimeError: crates are hard"}
    assert meta["failed_grasps_per_object"] == 3
    assert (meta["n_points"], meta["seed"]) == (64, 3)
    problems = validate_submission(
        out, object_ids=ref.object_ids, benchmark_sha256=ref.sha256, embedded=False
    )
    assert problems == []


def test_the_progress_bar_shows_each_object_once(
    module_file: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """In a log (stderr not a terminal), plain lines at most every few seconds (here, 0.9 s in
    all: the last line only), never a carriage-return update per object or postfix."""
    run_predictor(spec(module_file, "slow"), observations("abc"), progress=True)
    err = capsys.readouterr().err
    assert "\r" not in err
    lines = [line for line in err.splitlines() if line.startswith("predictor: ")]
    assert len(lines) == 1, lines
    assert lines[0].startswith("predictor: 3/3 object (100%), "), lines
    assert lines[0].endswith(", done, failed=0"), lines


def test_a_failed_object_weighs_as_much_as_the_largest_answer() -> None:
    from dg16m_env.subjects.predictor import failed_placeholders

    assert failed_placeholders({}).shape == (1, 2, 4, 4)  # nothing answered: one failure
    answered = {"a": np.zeros((2, 2, 4, 4)), "b": np.zeros((10, 2, 4, 4))}
    placeholders = failed_placeholders(answered)
    assert placeholders.shape == (10, 2, 4, 4)
    assert (np.linalg.norm(placeholders[:, :, :3, 3], axis=-1) >= 5.0).all()  # far off the object
