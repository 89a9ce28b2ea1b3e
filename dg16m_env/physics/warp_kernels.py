"""The small Warp kernels of a batched trial step (:mod:`dg16m_env.physics.warp_trials`).

Imported only when the optional ``warp`` extra is installed (this module imports ``warp`` at
the top; Warp reads the kernels' annotations, so they cannot be postponed). Warp compiles them
on first launch and caches the binaries on disk.
"""

import warp as wp


@wp.kernel
def set_wrench(
    wrench: wp.array2d(dtype=float),
    counter: wp.array(dtype=int),
    body: int,
    xfrc_applied: wp.array2d(dtype=wp.spatial_vector),
):
    """Write step ``counter[0] + counter[1]`` of the (T, 6) wrench schedule (force, torque in
    the world frame) on ``body`` of every world."""
    world = wp.tid()
    t = counter[0] + counter[1]
    xfrc_applied[world, body] = wp.spatial_vector(
        wrench[t, 0], wrench[t, 1], wrench[t, 2], wrench[t, 3], wrench[t, 4], wrench[t, 5]
    )


@wp.kernel
def measure(
    counter: wp.array(dtype=int),
    time: wp.array(dtype=float),
    qpos: wp.array2d(dtype=float),
    qvel: wp.array2d(dtype=float),
    act: wp.array2d(dtype=float),
    sensordata: wp.array2d(dtype=float),
    qpos_adr: int,
    qvel_adr: int,
    sensor_adr: wp.vec4i,
    anchors: wp.array2d(dtype=wp.vec3),
    body_points: wp.array2d(dtype=wp.vec3),
    reference: wp.array(dtype=wp.quat),
    out: wp.array3d(dtype=float),
):
    """The protocol's measures of every world after a step, at row ``counter[0]`` of ``out``
    (steps, worlds, ``dg16m_env.physics.warp_trials.MEASURES``): the float32 twin of
    ``dg16m_env.physics.trial.measure_steps``.

    The object's free joint sits at ``qpos_adr`` (position, quaternion w x y z) and ``qvel_adr``
    (linear velocity first). Slip: the largest distance over the anchors k between where the
    material point ``body_points[k]`` (in the object frame of the reference pose) is now and
    ``anchors[k]`` (where it was at the reference pose). Rotation from the reference orientation
    ``reference`` (a Warp quaternion, x y z w), as ``2 atan2(|v|, |w|)`` of the relative
    quaternion (the same angle as ``2 acos |w|``, without its loss of precision near 0).
    ``sensor_adr``: the object's contact count, its deepest contact distance, each hand's contact
    count.
    """
    world = wp.tid()
    t = counter[0]
    finite = wp.isfinite(time[world])
    for i in range(qpos.shape[1]):
        finite = finite and wp.isfinite(qpos[world, i])
    for i in range(qvel.shape[1]):
        finite = finite and wp.isfinite(qvel[world, i])
    for i in range(act.shape[1]):
        finite = finite and wp.isfinite(act[world, i])
    pos = wp.vec3(qpos[world, qpos_adr], qpos[world, qpos_adr + 1], qpos[world, qpos_adr + 2])
    rot = wp.normalize(
        wp.quat(
            qpos[world, qpos_adr + 4],
            qpos[world, qpos_adr + 5],
            qpos[world, qpos_adr + 6],
            qpos[world, qpos_adr + 3],
        )
    )
    slip = float(0.0)  # noqa: UP018  (Warp: float() declares a variable the loop may change)
    for k in range(anchors.shape[1]):
        moved = wp.quat_rotate(rot, body_points[world, k]) + pos - anchors[world, k]
        slip = wp.max(slip, wp.length(moved))
    relative = wp.mul(wp.quat_inverse(reference[world]), rot)
    axis = wp.vec3(relative[0], relative[1], relative[2])
    turn = 2.0 * wp.atan2(wp.length(axis), wp.abs(relative[3])) * 57.29577951308232
    vel = wp.vec3(qvel[world, qvel_adr], qvel[world, qvel_adr + 1], qvel[world, qvel_adr + 2])
    depth = float(0.0)  # noqa: UP018  (as above)
    if sensordata[world, sensor_adr[0]] > 0.0:
        depth = -sensordata[world, sensor_adr[1]]
    out[t, world, 0] = time[world]
    out[t, world, 1] = slip
    out[t, world, 2] = turn
    out[t, world, 3] = wp.where(finite, 1.0, 0.0)
    out[t, world, 4] = wp.length(vel)
    out[t, world, 5] = depth
    out[t, world, 6] = sensordata[world, sensor_adr[2]]
    out[t, world, 7] = sensordata[world, sensor_adr[3]]


@wp.kernel
def advance(counter: wp.array(dtype=int)):
    """Move to the next recorded step."""
    counter[0] = counter[0] + 1
