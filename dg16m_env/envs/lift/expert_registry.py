"""The Lift task's observation-feedback experts by name: ``dg16m demos collect --expert``,
:mod:`baselines.bc_lift` (the expert a dataset names labels its DAgger states) and
:mod:`baselines.lift_expert_robustness` make them here."""

from __future__ import annotations

from dg16m_env.envs.lift.experts import FeedbackLiftExpert
from dg16m_env.envs.lift.planning_expert import PlanningLiftExpert
from dg16m_env.envs.lift.recovering_expert import RecoveringLiftExpert

LIFT_EXPERTS: dict[str, type[FeedbackLiftExpert]] = {
    "feedback": FeedbackLiftExpert,
    "recovering": RecoveringLiftExpert,
    "planning": PlanningLiftExpert,
}
"""Name -> class of the experts of ``DualGraspLift-v1``..``-v3``:
:class:`~dg16m_env.envs.lift.experts.FeedbackLiftExpert`,
:class:`~dg16m_env.envs.lift.recovering_expert.RecoveringLiftExpert` and
:class:`~dg16m_env.envs.lift.planning_expert.PlanningLiftExpert` (which plans on the
``"pointcloud"`` observation's cloud: its ``OBS_MODE``; on other observations it is the
recovering expert)."""


def make_lift_expert(
    name: str, lift_height: float = 0.10, lift_margin: float = 0.03
) -> FeedbackLiftExpert:
    """A new expert ``name`` (a key of :data:`LIFT_EXPERTS`, or its class name, as a dataset
    records it); ``ValueError`` naming the choices for anything else."""
    by_class = {cls.__name__: cls for cls in LIFT_EXPERTS.values()}
    cls = LIFT_EXPERTS.get(name) or by_class.get(name)
    if cls is None:
        raise ValueError(
            f"expert: expected one of {sorted(LIFT_EXPERTS)} (or their class names "
            f"{sorted(by_class)}), found {name!r}"
        )
    return cls(lift_height=lift_height, lift_margin=lift_margin)
