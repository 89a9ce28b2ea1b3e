"""DualGraspLift-v0 at scale (issue 40, part 5), without a change of behaviour: a lazily read
benchmark holds the same objects as an eager read and reads none of them before it is used
(``gym.make(..., benchmark="real")`` then touches one object per reset), the step's physics loop
equals the plain loop bit for bit (sensors evaluated at the last substep only), and rendering
reuses its renderer. No timings here: ``bench/env_lift.py --speed`` measures them."""

from __future__ import annotations

import os
import pickle
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("mujoco")
gym = pytest.importorskip("gymnasium")

import mujoco  # noqa: E402

import dg16m_env  # noqa: E402, F401  (registers the environments)
from dg16m_env.benchmark.file import LazyBenchmarkObject, read_benchmark  # noqa: E402
from dg16m_env.benchmark.model import BenchmarkError  # noqa: E402
from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK  # noqa: E402
from dg16m_env.envs import NAMESPACE  # noqa: E402
from dg16m_env.envs.lift.experts import ScriptedLiftPolicy  # noqa: E402
from dg16m_env.envs.lift.v0 import DualGraspLiftEnv  # noqa: E402
from dg16m_env.physics.replay import RenderError, make_renderer  # noqa: E402

LIFT = f"{NAMESPACE}/DualGraspLift-v0"

# v0 is made on purpose: its deprecation and Gymnasium's note of a newer version are expected.
pytestmark = [
    pytest.mark.filterwarnings(
        "ignore:dg16m_env/DualGraspLift-v0 is deprecated:DeprecationWarning"
    ),
    pytest.mark.filterwarnings("ignore:.*is out of date.*upgrading to version:DeprecationWarning"),
]
TINY_REAL = Path(__file__).parent / "data" / "real_tiny" / "benchmark.h5"
STATE = mujoco.mjtState.mjSTATE_INTEGRATION


def _same(a: Any, b: Any) -> bool:
    if a is None or b is None:
        return a is b
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


@pytest.mark.parametrize("path", [TINY_REAL, EMBEDDED_BENCHMARK], ids=["meshes", "procedural"])
def test_a_lazy_read_holds_the_objects_of_an_eager_read(path: Path) -> None:
    eager = read_benchmark(path)
    lazy = read_benchmark(path, lazy=True)
    objects = lazy.objects[:3]
    assert all(isinstance(o, LazyBenchmarkObject) and not o.loaded for o in lazy.objects)
    # has_mesh, repr and pickling read nothing
    assert [o.has_mesh for o in lazy.objects] == [o.has_mesh for o in eager.objects]
    assert all("not read yet" in repr(o) for o in objects)
    copy = pickle.loads(pickle.dumps(lazy))
    assert not any(o.loaded for o in lazy.objects + copy.objects)
    for read in (lazy, copy):
        for a, b in zip(eager.objects[:3], read.objects[:3], strict=True):
            for name in ("object_id", "family", "seed", "file", "scale", "mass", "mesh_sha256"):
                assert getattr(a, name) == getattr(b, name)
            assert _same(a.center_of_mass, b.center_of_mass)
            assert _same(a.mesh_vertices, b.mesh_vertices)
            assert _same(a.mesh_faces, b.mesh_faces)
            assert len(a.parts) == len(b.parts)
            for pa, pb in zip(a.parts, b.parts, strict=True):
                assert (pa.kind, pa.size) == (pb.kind, pb.size)
                assert _same(pa.pose, pb.pose)
                assert _same(pa.vertices, pb.vertices)
            assert b.loaded
            assert repr(b) == repr(a)
    assert objects[0]._reader.reads == list(range(len(objects)))  # each object read once
    assert _same(eager.poses, lazy.poses)
    assert _same(eager.p("full"), lazy.p("full"))


def test_a_lazy_read_refuses_a_file_changed_since(tmp_path: Path) -> None:
    path = tmp_path / "b.h5"
    path.write_bytes(TINY_REAL.read_bytes())
    lazy = read_benchmark(path, lazy=True)
    stat = path.stat()
    os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000_000))
    with pytest.raises(BenchmarkError, match="changed since"):
        _ = lazy.objects[0].parts


def test_make_real_reads_no_object_until_reset_and_then_one() -> None:
    env = gym.make(LIFT, benchmark="real")
    try:
        objects = env.unwrapped.objects.ref.benchmark.objects
        assert len(objects) == 300
        assert not any(o.loaded for o in objects)
        reads = objects[0]._reader.reads
        assert reads == []
        chosen = objects[7].object_id
        env.reset(seed=0, options={"object_id": chosen})
        assert [objects[i].object_id for i in reads] == [chosen]
        assert [o.object_id for o in objects if o.loaded] == [chosen]
    finally:
        env.close()


def test_the_physics_loop_equals_the_plain_loop_bit_for_bit(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Each substep's inputs, recorded, replayed by the plain loop (targets written, sensors on
    at every substep) from the state before the step: the same state and sensors after it."""
    env = DualGraspLiftEnv(benchmark=TINY_REAL, target_grasp="benchmark")
    obs, _ = env.reset(seed=0)
    assert env._current is not None
    model, data = env._current.scene.model, env._current.data
    policy = ScriptedLiftPolicy()
    for _ in range(120):  # until the fingers touch the object: the contact sensors count
        obs, *_ = env.step(policy(obs))
        if data.sensordata[env._current.scene.finger_contacts].any():
            break
    assert data.sensordata[env._current.scene.finger_contacts].any()
    start = np.empty(mujoco.mj_stateSize(model, STATE))
    mujoco.mj_getState(model, data, start, STATE)
    inputs: list[np.ndarray] = []
    step = mujoco.mj_step

    def recording(m: mujoco.MjModel, d: mujoco.MjData, nstep: int = 1) -> None:
        inputs.append(np.concatenate([d.mocap_pos.ravel(), d.mocap_quat.ravel(), d.ctrl]))
        step(m, d, nstep=nstep)

    monkeypatch.setattr(mujoco, "mj_step", recording)
    env.step(policy(obs))
    monkeypatch.setattr(mujoco, "mj_step", step)
    assert len(inputs) == env.substeps
    assert model.opt.disableflags == 0  # the sensors switched back on
    after = np.empty_like(start)
    mujoco.mj_getState(model, data, after, STATE)

    plain = mujoco.MjData(model)
    mujoco.mj_setState(model, plain, start, STATE)
    for row in inputs:
        plain.mocap_pos[:] = row[:6].reshape(2, 3)
        plain.mocap_quat[:] = row[6:14].reshape(2, 4)
        plain.ctrl[:] = row[14:]
        mujoco.mj_step(model, plain)
    expected = np.empty_like(start)
    mujoco.mj_getState(model, plain, expected, STATE)
    assert _same(after, expected)
    assert _same(data.sensordata, plain.sensordata)
    assert _same(data.xpos, plain.xpos)
    assert _same(data.qacc, plain.qacc)
    env.close()


def test_render_reuses_its_renderer_and_repeats_its_frame() -> None:
    env = gym.make(LIFT, benchmark=TINY_REAL, render_mode="rgb_array", width=64, height=48)
    try:
        env.reset(seed=0)
        try:
            make_renderer(env.unwrapped._current.scene.model, 8, 8).close()
        except RenderError:
            pytest.skip("no offscreen OpenGL context here")
        first = env.render()
        renderer = env.unwrapped._renderer
        again = env.render()
        assert env.unwrapped._renderer is renderer
        assert first.shape == (48, 64, 3)
        assert np.array_equal(first, again)
        env.step(env.action_space.sample())
        env.render()
        assert env.unwrapped._renderer is renderer
    finally:
        env.close()
