"""dg16m_env: the MuJoCo dual-gripper scene, trial protocol, benchmark, what gets scored, the
evaluators, the Gymnasium environments and their commands. Builds on :mod:`dataset_gen`;
environments register on import.

The package is laid out in layers; a module imports only from its own layer and the layers
below it (``tests/test_import_circles.py`` keeps it so):

=====  ==========================  ==============================================================
layer  folder                      what lives there
=====  ==========================  ==============================================================
7      :mod:`dg16m_env.cli`        the ``dg16m`` subcommands of this package
6      :mod:`dg16m_env.envs`       the Gymnasium tasks, their rewards and experts
5      :mod:`dg16m_env.evaluators` scoring: registry, results, fce, gsr, classifier, policy
4      :mod:`dg16m_env.training`   a dataset folder as torch datasets (clouds, poses, labels)
3      :mod:`dg16m_env.subjects`   what gets scored: submission files, predictors, observations
2      :mod:`dg16m_env.benchmark`  the benchmark: model, file, sources, building, reports
1      :mod:`dg16m_env.physics`    MuJoCo only: scenes, the trial protocol and its engines, labels
0      :mod:`dg16m_env.rates`      object-resampled rates (numpy only)
=====  ==========================  ==============================================================

Modules that moved in 0.2.0 keep their old names for one release (``dg16m_env._compat``:
``import dg16m_env.trial`` still works and warns).

Rendering is offscreen: unless ``MUJOCO_GL`` is already set, it defaults to ``egl`` here, before
MuJoCo or dm_control are imported (``osmesa`` is the software fallback; both need the system
libraries ``libegl1`` / ``libosmesa6``). Without it dm_control tries an X11 window and warns.
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

from dg16m_env import _compat, envs  # envs registers the Gymnasium environments

_compat.install()  # the old module names (dg16m_env.trial, ...) for one release

__all__ = ["envs"]
