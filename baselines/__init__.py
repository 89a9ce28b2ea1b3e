"""baselines: grasp classifiers (torch), RL policies (stable-baselines3) and pairing baselines,
scored through the evaluators of :mod:`dg16m_env`."""
