"""dg16m_env: the MuJoCo dual-gripper scene, trial protocol, Gymnasium environments, benchmark
and evaluator registry. Builds on :mod:`dataset_gen`; environments register on import.

Rendering is offscreen: unless ``MUJOCO_GL`` is already set, it defaults to ``egl`` here, before
MuJoCo or dm_control are imported (``osmesa`` is the software fallback; both need the system
libraries ``libegl1`` / ``libosmesa6``). Without it dm_control tries an X11 window and warns.
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

from dg16m_env import envs  # registers the Gymnasium environments (after MUJOCO_GL is set)

__all__ = ["envs"]
