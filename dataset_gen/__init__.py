"""dataset_gen: the offline DG16M generator's foundations.

Modules: ``objects`` (load, clean, centre, scale, mass properties, convex parts),
``procedural`` (the embedded object library), ``library`` (object folders), ``gripper``
(Panda and Robotiq 2F-85 models, grasp frame convention, ``contacts_from_pose``),
``io`` (DG16M release schema, ACRONYM files, manifests), ``render`` (offscreen pictures),
``cli``/``commands`` (the ``dg16m`` command). Nothing here imports MuJoCo or torch.
"""
