"""dg16m_env: the MuJoCo dual-gripper scene, trial protocol, Gymnasium environments, benchmark
and evaluator registry. Builds on :mod:`dataset_gen`; environments register on import."""
