"""Grasps: the gripper and the single- and dual-arm grasps made with it (floor 2 of
:mod:`dataset_gen`).

``gripper`` (models, grasp frame, ``contacts_from_pose``), ``sampling`` (antipodal single-arm
grasps), ``clearance`` (the open-hand clearance rule shared with the simulator), ``pairing``
(dual-arm pairs and their ablations), ``pairing_checks`` (input checks), ``pairing_selection``
(the stored pairs), ``robust`` (the robust criterion).

May import: :mod:`dg16m_core`, :mod:`dataset_gen.objects.grasp_object`, :mod:`dataset_gen.force_closure`,
:mod:`dataset_gen.io` and this folder.
"""
