"""State save and restore of the Lift task (v1 and later): :func:`get_state` gathers everything
the next steps depend on as plain values, :func:`set_state` restores it exactly on the same
machine and build (the same later steps, bit for bit). The env's methods
(:meth:`~dg16m_env.envs.lift.task.LiftEnv.get_state`, ``set_state``) call these, passing
themselves (typed ``Any``: this module sits below the task).
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np

STATE_VERSION = 1
"""Version of the :func:`get_state` dictionary."""

STATE_SPEC = mujoco.mjtState.mjSTATE_INTEGRATION
"""The MuJoCo state saved (positions, velocities, controls, mocap targets, warm start, time)."""

STATE_KEYS = (
    "version",
    "object_id",
    "physics",
    "commanded_centres",
    "commanded_rotations",
    "commanded_quaternions",
    "target_grasp",
    "target_row",
    "rest_height",
    "hold_anchor",
    "hold_count",
    "elapsed_steps",
    "episode_steps",
    "previous_action",
    "ended",
    "cloud",
)
"""The keys of a :func:`get_state` dictionary."""


def get_state(env: Any) -> dict[str, Any]:
    """Everything the next steps of ``env`` depend on, as plain values (numpy arrays, numbers,
    str): MuJoCo's integration state (``mjSTATE_INTEGRATION``), the commanded hand poses, the
    target grasp, the hold, the step count and the previous action."""
    if env._current is None:
        raise RuntimeError("get_state: expected reset() before get_state(), found no episode")
    model, data = env._current.scene.model, env._current.data
    physics = np.empty(mujoco.mj_stateSize(model, STATE_SPEC))
    mujoco.mj_getState(model, data, physics, STATE_SPEC)
    return {
        "version": STATE_VERSION,
        "object_id": env.object_id,
        "physics": physics,
        "commanded_centres": env._target_pos.copy(),
        "commanded_rotations": env._target_rot.copy(),
        "commanded_quaternions": env._target_quat.copy(),
        "target_grasp": None if env._grasp is None else env._grasp.copy(),
        "target_row": int(env._target_row),
        "rest_height": float(env._rest_com_z),
        "hold_anchor": None if env._hold_anchor is None else env._hold_anchor.copy(),
        "hold_count": int(env._hold_count),
        "elapsed_steps": int(env._elapsed),
        "episode_steps": int(env._steps_total),
        "previous_action": env._previous_action.copy(),
        "ended": env._ended,
        "cloud": None if env._cloud is None else tuple(a.copy() for a in env._cloud),
    }


def _check_state(env: Any, state: Any) -> None:
    if not isinstance(state, dict) or state.get("version") != STATE_VERSION:
        found = state.get("version") if isinstance(state, dict) else type(state).__name__
        raise ValueError(
            f"state: expected a get_state() dictionary of version {STATE_VERSION}, found {found!r}"
        )
    missing = sorted(set(STATE_KEYS) - set(state))
    if missing:
        raise ValueError(
            f"state: expected the keys of a get_state() dictionary, found {missing} missing"
        )
    object_id = state.get("object_id")
    if object_id not in env.objects.ref.object_ids:
        raise ValueError(
            f"state['object_id']: expected an object of this env's benchmark, found {object_id!r}"
        )


def set_state(env: Any, state: dict[str, Any]) -> None:
    """Restore a :func:`get_state` dictionary into ``env`` (the caller observes after).

    Raises:
        ValueError: not such a dictionary (a missing key, another object, wrong shapes).
    """
    _check_state(env, state)
    object_id = state["object_id"]
    item = env._object(object_id)
    model, data = item.scene.model, item.data
    physics = np.asarray(state["physics"], dtype=np.float64)
    size = mujoco.mj_stateSize(model, STATE_SPEC)
    if physics.shape != (size,):
        raise ValueError(
            f"state['physics']: expected shape ({size},) for object {object_id!r}, found "
            f"{physics.shape}"
        )
    env._reset_state()
    env.object_id, env._current = object_id, item
    mujoco.mj_setState(model, data, physics, STATE_SPEC)
    mujoco.mj_forward(model, data)
    env._target_pos = np.array(state["commanded_centres"], dtype=np.float64)
    env._target_rot = np.array(state["commanded_rotations"], dtype=np.float64)
    env._target_quat = np.array(state["commanded_quaternions"], dtype=np.float64)
    grasp = state["target_grasp"]
    env._grasp = None if grasp is None else np.array(grasp, dtype=np.float64)
    env._target_row = int(state["target_row"])
    env._rest_com_z = float(state["rest_height"])
    anchor = state["hold_anchor"]
    env._hold_anchor = None if anchor is None else np.array(anchor, dtype=np.float64)
    env._hold_count = int(state["hold_count"])
    env._elapsed = int(state["elapsed_steps"])
    env._steps_total = int(state["episode_steps"])
    env._previous_action = np.array(state["previous_action"], dtype=np.float64)
    env._ended = str(state["ended"])
    cloud = state["cloud"]
    env._cloud = None if cloud is None else tuple(np.array(a) for a in cloud)  # type: ignore[assignment]
    if env.render_mode == "rgb_array":
        env._camera = None
