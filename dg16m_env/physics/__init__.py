"""The physics layer: MuJoCo only. The dual-gripper trial scene (:mod:`.scene`) and the Lift task's
table scene (:mod:`.lift_scene`), the choice of simulator (:mod:`.simulator`), the trial protocol
(:mod:`.trial_protocol`: phases, validity check, schedule, controls) with its measures and judge
(:mod:`.trial_measures`), the engines that run trials (:mod:`.trial`: C MuJoCo batches and the
engine choice; :mod:`.warp_trials` and :mod:`.warp_kernels`: MuJoCo Warp), success
probabilities over perturbed trials (:mod:`.labels`), the batched GSR core: many grasps on many
objects over a pool (:mod:`.success_probabilities`), re-seating hands (:mod:`.reseat`),
step-by-step replay and its pictures (:mod:`.replay`, its files :mod:`.replay_files`) and
cameras (:mod:`.cameras`).

Layer rule: modules here import MuJoCo, numpy, :mod:`dataset_gen` and each other, never a layer
of :mod:`dg16m_env` above (benchmark, subjects, evaluators, envs, cli). The protocol is defined
once, here, for every engine: a change to how a trial judges success is a change to
:mod:`.trial_protocol` or :mod:`.trial_measures`.
"""
