"""Old import paths of :mod:`dg16m_env`, kept for one release after the package was laid out in
layers (0.2.0; see ``CHANGELOG.md``): importing one still works and raises a
:class:`DeprecationWarning` that names the new home.

* :data:`MOVED_MODULES`: a module that moved whole (``dg16m_env.trial`` ->
  ``dg16m_env.physics.trial``) is the same module object under its old name, so reading,
  patching or reloading it through either name acts on the one module; a module that was cut in
  pieces (``dg16m_env.submission``) is a small module that looks each name up in its pieces, in
  order. (The names that had left ``dg16m_env.envs.dual_grasp_lift`` in 0.2.0 are found in
  its pieces: the module itself moved into :mod:`dg16m_env.envs.lift`.)

The mechanism is the kernel's (:mod:`dg16m_core.compat`, standard library only); this module is
the table. Redirects are resolved by name when they are used: this table is not a dependency of
the layers, and nothing in the package imports through it.
"""

from __future__ import annotations

from dg16m_core import compat
from dg16m_core.compat import REMOVED_IN

__all__ = ["MOVED_MODULES", "REMOVED_IN", "install"]

_P = "dg16m_env"

MOVED_MODULES: dict[str, tuple[str, ...]] = {
    # physics: MuJoCo scenes, the trial protocol and its engines, labels, replay
    f"{_P}.scene": (f"{_P}.physics.scene",),
    f"{_P}.simulator": (f"{_P}.physics.simulator",),
    f"{_P}.trial": (f"{_P}.physics.trial",),
    f"{_P}.trial_protocol": (f"{_P}.physics.trial_protocol", f"{_P}.physics.trial_measures"),
    f"{_P}.warp_trials": (f"{_P}.physics.warp_trials",),
    f"{_P}.warp_kernels": (f"{_P}.physics.warp_kernels",),
    f"{_P}.labels": (f"{_P}.physics.labels",),
    f"{_P}.replay": (f"{_P}.physics.replay",),
    f"{_P}.reseat": (f"{_P}.physics.reseat",),
    f"{_P}.gsr": (f"{_P}.physics.success_probabilities",),
    f"{_P}.physics.gsr_core": (f"{_P}.physics.success_probabilities",),
    f"{_P}.envs.cameras": (f"{_P}.physics.cameras",),
    f"{_P}.envs.lift_scene": (f"{_P}.physics.lift_scene",),
    # benchmark: the model, the file, sources, building, short names, reports, real objects
    f"{_P}.benchmark_report": (
        f"{_P}.benchmark.report",
        f"{_P}.benchmark.report_text",
        f"{_P}.benchmark.report_plot",
    ),
    f"{_P}.real_benchmark": (f"{_P}.benchmark.real",),
    f"{_P}.real_build_state": (f"{_P}.benchmark.real_build_state",),
    f"{_P}.evaluators.context": (f"{_P}.benchmark.ref",),
    # subjects: what gets scored
    f"{_P}.submission": (
        f"{_P}.subjects.submission",
        f"{_P}.subjects.submission_reader",
        f"{_P}.subjects.submission_writer",
    ),
    f"{_P}.predictor": (f"{_P}.subjects.predictor", f"{_P}.subjects.predictor_process"),
    f"{_P}.observation": (f"{_P}.subjects.observation",),
    # cli: the dg16m subcommands
    f"{_P}.benchmark_command": (f"{_P}.cli.benchmark",),
    f"{_P}.evaluate_command": (f"{_P}.cli.evaluate",),
    f"{_P}.sim_command": (f"{_P}.cli.sim",),
    # envs: Lift's vector env, in the Lift package
    f"{_P}.envs.lift_vector": (f"{_P}.envs.lift.vector",),
    # envs: the Lift task, one package (one task class, versions as records)
    f"{_P}.envs.dual_grasp_lift": (
        f"{_P}.envs.lift.v0",
        f"{_P}.envs.lift.task",
        f"{_P}.envs.lift.scenes",
        f"{_P}.envs.lift.measures",
        f"{_P}.envs.lift.spaces",
        f"{_P}.envs.lift.experts",
        f"{_P}.envs.lift.reward",
    ),
    f"{_P}.envs.dual_grasp_lift_v1": (
        f"{_P}.envs.lift.v1",
        f"{_P}.envs.lift.task",
        f"{_P}.envs.lift.state",
        f"{_P}.envs.lift.observations",
        f"{_P}.envs.lift.reward",
    ),
    f"{_P}.envs.dual_grasp_lift_v2": (f"{_P}.envs.lift.v2", f"{_P}.envs.lift.arithmetic"),
    f"{_P}.envs.lift_demos": (f"{_P}.envs.lift.demos", f"{_P}.envs.lift.demo_files"),
    f"{_P}.envs.lift_expert": (f"{_P}.envs.lift.experts",),
    f"{_P}.envs.lift_feedback_expert": (f"{_P}.envs.lift.experts",),
    f"{_P}.envs.lift_kernels": (f"{_P}.envs.lift.kernels",),
    f"{_P}.envs.lift_measures": (f"{_P}.envs.lift.measures",),
    f"{_P}.envs.lift_observations": (f"{_P}.envs.lift.observations",),
    f"{_P}.envs.lift_reward": (f"{_P}.envs.lift.reward",),
    f"{_P}.envs.lift_spaces": (f"{_P}.envs.lift.spaces",),
    f"{_P}.envs.lift_targets": (f"{_P}.envs.lift.targets",),
}
"""Old module name -> its new module(s); a name is looked up in them in order."""


def install() -> None:
    """Put the finder of the old module names on ``sys.meta_path`` (once)."""
    compat.install(MOVED_MODULES)
