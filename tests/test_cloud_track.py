"""The cloud track: the harness's depth-camera observation (no mesh), the Landlock sandbox that
keeps the predictor's process from the benchmark, and the provenance its submissions record."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import trimesh

from baselines.cloud_predictor import depth_views, random_partial_predictor, stream_name
from dg16m_core.cli import main
from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK
from dg16m_env.evaluators import load_benchmark_ref
from dg16m_env.subjects.cloud_observation import (
    OBSERVATION_KEYS,
    CloudTrack,
    cloud_observation,
    edge_pixels,
)
from dg16m_env.subjects.observation import ObservationError
from dg16m_env.subjects.predictor import submission_from_predictor
from dg16m_env.subjects.predictor_process import PredictorSpec
from dg16m_env.subjects.sandbox import allowed_entries, landlock_abi
from dg16m_env.subjects.submission import EMBEDDED
from dg16m_env.subjects.submission_reader import read_submission, validate_submission
from dg16m_env.subjects.submission_writer import write_submission
from dg16m_env.subjects.track import TRACKS, track_name

PREDICTORS = '''
import numpy as np

MESH_KEYS = ("mesh_vertices", "mesh_faces", "object_id", "family", "bounds")


def grasps(obs):
    """One dual grasp around the cloud's centre; refuses an observation with the mesh."""
    leaked = [k for k in MESH_KEYS if k in obs]
    if leaked:
        raise AssertionError(f"the observation holds {leaked}")
    centre = np.asarray(obs["points"], dtype=np.float64).mean(axis=0)
    p = np.tile(np.eye(4), (1, 2, 1, 1))
    p[0, 0, :3, 3] = centre + (0.3, 0.0, 0.0)
    p[0, 1, :3, 3] = centre - (0.3, 0.0, 0.0)
    return p


def peek(obs):
    """Reads the benchmark file first (the path comes from the environment's imports)."""
    from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK

    with open(EMBEDDED_BENCHMARK, "rb") as handle:
        handle.read(8)
    return grasps(obs)
'''

needs_landlock = pytest.mark.skipif(
    landlock_abi() < 1, reason="Linux Landlock is unavailable here (kernel, OS or container)"
)


@pytest.fixture(scope="module")
def ref():
    return load_benchmark_ref(None)


@pytest.fixture(scope="module")
def crate(ref):
    return next(o for o in ref.benchmark.objects if o.object_id == "crate-1000000").load(None)


@pytest.fixture(scope="module")
def observed(crate):
    return cloud_observation(crate), cloud_observation(crate, CloudTrack(noise="none"))


@pytest.fixture
def predictors(tmp_path: Path) -> Path:
    file = tmp_path / "cloud_predictors.py"
    file.write_text(textwrap.dedent(PREDICTORS))
    return file


def test_the_observation_holds_no_mesh_and_its_shapes_agree(observed):
    obs, _ = observed
    assert tuple(obs) == OBSERVATION_KEYS
    for key in ("mesh_vertices", "mesh_faces", "object_id", "family", "bounds"):
        assert key not in obs
    depth, poses, k = obs["depth"], obs["camera_poses"], obs["intrinsics"]
    assert depth.shape == (2, 128, 128)
    assert depth.dtype == np.float32
    assert poses.shape == (2, 4, 4)
    assert k.shape == (3, 3)
    n = int((depth > 0).sum())
    assert obs["points"].shape == obs["normals"].shape == (n, 3)
    assert obs["points"].dtype == obs["normals"].dtype == np.float32
    assert obs["pixels"].shape == (n, 3)
    assert np.allclose(np.linalg.norm(obs["normals"], axis=1), 1.0, atol=1e-5)
    rotation = poses[:, :3, :3]
    assert np.allclose(rotation @ rotation.transpose(0, 2, 1), np.eye(3), atol=1e-9)
    # each point is its pixel's depth back-projected (OpenCV axes) into the object frame
    c, i, j = obs["pixels"].T
    z = depth[c, i, j].astype(np.float64)
    local = np.stack([(j + 0.5 - k[0, 2]) * z / k[0, 0], (i + 0.5 - k[1, 2]) * z / k[1, 1], z], 1)
    world = np.einsum("nij,nj->ni", rotation[c], local) + poses[c, :3, 3]
    assert np.abs(world - obs["points"]).max() < 1e-4
    # normals face their camera (or are seen edge on)
    to_camera = poses[c, :3, 3] - obs["points"]
    assert (np.einsum("ni,ni->n", to_camera, obs["normals"]) > -1e-6).all()


def test_same_seeds_same_bytes_and_noise_changes_the_depth(crate, observed):
    kinect, ideal = observed
    again = cloud_observation(crate)
    for key in OBSERVATION_KEYS:
        assert np.array_equal(np.asarray(kinect[key]), np.asarray(again[key])), key
    assert np.array_equal(kinect["camera_poses"], ideal["camera_poses"])  # the same cameras
    assert not np.array_equal(kinect["depth"], ideal["depth"])
    other = cloud_observation(crate, CloudTrack(noise_seed=1))
    assert not np.array_equal(kinect["depth"], other["depth"])
    moved = cloud_observation(crate, CloudTrack(camera_seed=1))
    assert not np.array_equal(kinect["camera_poses"], moved["camera_poses"])
    # kinect: pixels go missing (grazing angles, edges), none appear
    assert ((kinect["depth"] > 0) <= (ideal["depth"] > 0)).all()
    assert (kinect["depth"] > 0).sum() < (ideal["depth"] > 0).sum()
    # ideal depth lies on the mesh; kinect's lies off it by millimetres
    mesh = trimesh.Trimesh(crate.mesh.vertices, crate.mesh.faces, process=False)
    for obs, low, high in ((ideal, 0.0, 1e-5), (kinect, 2e-4, 1e-2)):
        _, distance, _ = trimesh.proximity.closest_point(mesh, obs["points"][::40].astype(float))
        assert low <= np.median(distance) < high


def test_edges_and_bad_tracks():
    depth = np.zeros((5, 5))
    depth[1:4, 1:4] = 1.0
    depth[2, 2] = 1.5  # a step of 0.5 m
    edge = edge_pixels(depth)
    assert edge[1:4, 1:4].all()
    assert not edge[depth == 0].any()
    depth[2, 2] = 1.001
    assert not edge_pixels(depth)[2, 2]
    with pytest.raises(ObservationError, match="noise: expected one of"):
        CloudTrack(noise="lidar")
    with pytest.raises(ObservationError, match="n_cameras"):
        CloudTrack(n_cameras=0)


def test_the_baseline_reads_the_harness_cameras(observed):
    kinect, ideal = observed
    for c in range(2):  # each camera's points lie on the surface their pixels saw
        one = {
            "depth": ideal["depth"][c : c + 1],
            "camera_poses": ideal["camera_poses"][c : c + 1],
            "intrinsics": ideal["intrinsics"],
        }
        seen = ideal["points"][ideal["pixels"][:, 0] == c].astype(np.float64)
        assert np.abs(depth_views(one).occlusion_depth(seen)).max() < 1e-5
    assert depth_views(ideal).seen_free(ideal["points"] + [0.0, 0.0, 5.0], 0.01).sum() == 0
    assert stream_name(kinect) == stream_name(dict(kinect))
    assert stream_name(kinect) != stream_name(ideal)
    poses, scores = random_partial_predictor(kinect)
    assert poses.shape[1:] == (2, 4, 4)
    assert scores.shape == (len(poses),)
    assert np.array_equal(random_partial_predictor(kinect)[0], poses)


def test_a_bad_track_in_a_submission_is_a_problem(tmp_path: Path, ref):
    poses = {i: np.tile(np.eye(4), (1, 2, 1, 1)) for i in ref.object_ids}
    for i in poses:
        poses[i][0, 1, 0, 3] = 0.5
    assert TRACKS == ("mesh", "cloud")
    assert track_name({}) == "mesh"
    with pytest.raises(ValueError, match="expected an object with 'name'"):
        track_name({"track": {"name": "lidar"}})
    good = write_submission(
        tmp_path / "good.h5", poses, benchmark=EMBEDDED, metadata={"track": {"name": "cloud"}}
    )
    assert validate_submission(good, object_ids=ref.object_ids) == []
    bad = write_submission(
        tmp_path / "bad.h5", poses, benchmark=EMBEDDED, metadata={"track": "lidar"}
    )
    problems = validate_submission(bad, object_ids=ref.object_ids)
    assert [p.place for p in problems] == ["attrs/metadata"]
    assert "expected an object with 'name' one of ('mesh', 'cloud')" in problems[0].message


def test_allowed_entries_never_grant_a_forbidden_path(tmp_path: Path):
    (tmp_path / "keep").mkdir()
    (tmp_path / "keep" / "a.txt").write_text("a")
    (tmp_path / "secret").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "secret")
    granted = {path for path, _ in allowed_entries([tmp_path / "secret"])}
    assert str(tmp_path / "keep") in granted
    assert str(tmp_path / "secret") not in granted
    assert str(tmp_path / "link") not in granted
    assert str(tmp_path) not in granted  # an ancestor: walked into, not granted whole


SANDBOXED = """
import os
import sys

from dg16m_env.subjects.sandbox import restrict_reading


def parent_memory():
    maps = open(f"/proc/{os.getppid()}/maps").read().splitlines()
    with open(f"/proc/{os.getppid()}/mem", "rb") as mem:
        mem.seek(int(maps[0].split("-")[0], 16))
        return mem.read(16)


try:
    parent_memory()  # allowed before, unless Yama's ptrace scope forbids it
except PermissionError:
    pass
print(restrict_reading([sys.argv[1]]))
for read in (lambda: open(sys.argv[1], "rb").read(), parent_memory):
    try:
        read()
        print("read")
    except PermissionError:
        print("refused")
print(open(sys.argv[2]).read())
"""


@needs_landlock
def test_a_restricted_process_reads_neither_the_file_nor_its_parents_memory(tmp_path: Path):
    secret, other = tmp_path / "secret.h5", tmp_path / "other.txt"
    secret.write_bytes(b"mesh")
    other.write_text("fine")
    done = subprocess.run(
        [sys.executable, "-c", SANDBOXED, str(secret), str(other)],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    assert done.stdout.split() == [f"landlock-abi-{landlock_abi()}", "refused", "refused", "fine"]


@needs_landlock
def test_the_predictor_process_cannot_read_the_benchmark(tmp_path: Path, predictors: Path, ref):
    path, run = submission_from_predictor(
        PredictorSpec(f"{predictors}:peek"),
        tmp_path / "peek.h5",
        benchmark=ref.first(2),
        track="cloud",
        progress=False,
    )
    assert run.sandbox == f"landlock-abi-{landlock_abi()}"
    assert set(run.errors) == set(ref.object_ids[:2])
    for message in run.errors.values():
        assert message.splitlines()[-1].startswith("PermissionError")
        assert str(EMBEDDED_BENCHMARK) in message
    track = read_submission(path, object_ids=ref.object_ids[:2]).metadata["track"]
    assert track["name"] == "cloud"
    assert track["sandbox"] == run.sandbox


def test_a_cloud_track_run_records_its_track(tmp_path: Path, predictors: Path, capsys):
    out = tmp_path / "cloud.json"
    argv = ["evaluate", "--predictor", f"{predictors}:grasps", "--track", "cloud", "--limit", "2"]
    argv += ["--evaluators", "fce", "--out", str(out), "--noise-seed", "3", "--no-progress"]
    assert main(argv) == 0
    assert "failed on" not in capsys.readouterr().out
    results = json.loads(out.read_text())
    assert results["subject"]["track"] == "cloud"
    assert results["results"]["fce"]["subject"]["track"] == "cloud"
    submission = Path(results["subject"]["file"])
    metadata = read_submission(submission, object_ids=results["subject"]["objects"]["subset"])
    track = metadata.metadata["track"]
    assert track["name"] == "cloud"
    assert track["noise"] == "kinect"
    assert track["noise_seed"] == 3
    assert track["cameras"] == 2
    assert track["camera_seed"] == 0
    assert track["predictor_sha256"] != "unknown"
    assert track["harness_version"] >= 1
    assert track["sandbox"] == (f"landlock-abi-{landlock_abi()}" if landlock_abi() else "none")
    # --track needs a predictor: a submission file declares its own
    assert main(["evaluate", str(submission), "--track", "cloud", "--limit", "2"]) == 2
    assert "--track cloud: expected --predictor" in capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.parametrize(
    "name",
    [
        "cgdf_partial_predictor",
        "pointnetgpd_partial_predictor",
        "random_partial_predictor",
        "cgdf_completed_predictor",
        "random_completed_predictor",
        "cgdf_robust_predictor",
        "random_robust_predictor",
    ],
)
def test_the_registered_cloud_predictors_run_on_the_cloud_track(tmp_path: Path, ref, name: str):
    objects = ["tub-1000000", "chair-1000000", "shelf-1000000"]
    path, run = submission_from_predictor(
        PredictorSpec(f"baselines.cloud_predictor:{name}"),
        tmp_path / f"{name}.h5",
        benchmark=ref.subset(objects),
        track="cloud",
        progress=False,
    )
    assert run.errors == {}
    assert read_submission(path, object_ids=objects).metadata["track"]["name"] == "cloud"


def test_the_provenance_hashes_a_module_target_of_an_installed_package() -> None:
    """``baselines.cloud_predictor:...`` (the package installed in editable mode, not on
    ``sys.path``): its source file is found and hashed, not reported "unknown"."""
    import hashlib
    import importlib.util

    from dg16m_env.subjects.track import predictor_sha256

    spec = importlib.util.find_spec("baselines.cloud_predictor")
    assert spec is not None
    assert spec.origin is not None
    expected = hashlib.sha256(Path(spec.origin).read_bytes()).hexdigest()
    assert predictor_sha256("baselines.cloud_predictor:cgdf_robust_predictor") == expected
    assert predictor_sha256("no_such_package.module:f") == "unknown"
