"""Reset options and target dual grasps of ``dg16m_env/DualGraspLift-v0``: the options a reset
takes (:func:`check_reset_options`) and the ``target_grasp`` option checked against the
benchmark (:func:`parse_target_option`). How a target is drawn and shown is documented in
:mod:`dg16m_env.envs.lift.v0` (*Target grasp*).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from dataset_gen.objects.grasp_object import is_rigid
from dg16m_env.benchmark.model import Benchmark


def check_reset_options(options: Mapping[str, Any] | None) -> dict[str, Any]:
    """The reset options as a dict (keys ``object_id`` and ``target_grasp`` only).

    Raises:
        ValueError: not a mapping, or other keys.
    """
    if options is None:
        return {}
    if not isinstance(options, Mapping):
        raise ValueError(f"options: expected a mapping or None, found {type(options).__name__}")
    unknown = sorted(set(options) - {"object_id", "target_grasp"})
    if unknown:
        raise ValueError(f"options: expected keys 'object_id', 'target_grasp', found {unknown}")
    return dict(options)


def parse_target_option(
    value: Any, object_id: str | None, bench: Benchmark
) -> tuple[Any, str | None]:
    """The reset option ``target_grasp`` checked against ``bench``: (kind, object id), kind is
    None, ``"benchmark"``, a row (int) or (2, 4, 4) poses (see *Target grasp* in
    :mod:`dg16m_env.envs.lift.v0`).

    Raises:
        ValueError: a row outside the benchmark or of another object than ``object_id``, or
            anything else than None, ``"benchmark"``, a row or (2, 4, 4) rigid poses.
    """
    if value is None or (isinstance(value, str) and value == "benchmark"):
        return value, object_id
    if isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_)):
        row = int(value)
        if not 0 <= row < bench.n:
            raise ValueError(
                f"options['target_grasp']: expected a benchmark row in [0, {bench.n}), found {row}"
            )
        owner = bench.objects[int(bench.object_index[row])].object_id
        if object_id is not None and object_id != owner:
            raise ValueError(
                f"options['target_grasp']: expected a row of object {object_id!r}, found "
                f"row {row} of {owner!r}"
            )
        return row, owner
    if isinstance(value, str):
        raise ValueError(
            "options['target_grasp']: expected None, 'benchmark', a row index or (2, 4, 4) "
            f"hand poses, found {value!r}"
        )
    try:
        poses = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        poses = np.zeros(0)
    if poses.shape != (2, 4, 4) or not bool(np.all(is_rigid(poses, atol=1e-5))):
        raise ValueError(
            "options['target_grasp']: expected None, 'benchmark', a row index or (2, 4, 4) "
            f"finite rigid hand poses (gripper -> object frame, m), found "
            f"{poses.shape if poses.size else type(value).__name__}"
        )
    return poses.copy(), object_id
