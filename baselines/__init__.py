"""baselines: grasp classifiers (torch), RL policies (stable-baselines3) and pairing baselines,
scored through the evaluators of :mod:`dg16m_env`.

Modules renamed in 0.2.0 keep their old names for one release (``baselines._compat``:
``import baselines.pairing`` still works and warns)."""

from baselines import _compat

_compat.install()  # the old module names (baselines.pairing, baselines.commands) for one release
