"""The Lift task (``dg16m_env/DualGraspLift-v*``) as one package: its environment versions,
reward terms, experts, demonstrations and vector env (:mod:`.vector`).

* The task is one class, :class:`.task.LiftEnv`; its registered versions differ only by a
  frozen record read at construction (:mod:`.versions`: physics step, reward, observation,
  episode bookkeeping, arithmetic, success rule). :mod:`.v0`, :mod:`.v1`, :mod:`.v2`,
  :mod:`.v3` document each version and name its class (``DualGraspLiftEnv``,
  ``DualGraspLiftV1Env``, ``DualGraspLiftV2Env``, ``DualGraspLiftV3Env``: the task class bound
  to its record). v3, the newest, is the one to use for new work; v0 is deprecated (its reward
  pays a hover more than a success) and removed in 0.3.0.
* Below the task: :mod:`.scenes` (per-object data, reset draws), :mod:`.arithmetic` (a step's
  targets, measures and observation; numpy for v0 and v1, the compiled :mod:`.kernels` for
  v2 and v3), :mod:`.measures` (hold, termination), :mod:`.reward`, :mod:`.spaces`,
  :mod:`.observations`, :mod:`.targets` (reset options), :mod:`.state` (save and restore).
* Beside it: :mod:`.experts` (the scripted and the feedback expert),
  :mod:`.recovering_expert` (an expert that recovers from pushes), :mod:`.expert_registry`
  (the experts by name), :mod:`.demos` (collecting
  demonstrations) and :mod:`.demo_files` (their Minari files: reading, replaying), and the
  vector env: :mod:`.vector` (``LiftVectorEnv``, ``gym.make_vec``'s default for v2 and v3: blocks of
  environments in this process and worker processes) on :mod:`.vector_block` (one block, its
  info records and their batching).

Layer rule: modules here import the evaluators, subjects, benchmark and physics layers and
:mod:`dg16m_env.envs`' shared modules, never :mod:`dg16m_env.cli`.
"""
