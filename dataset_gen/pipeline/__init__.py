"""Pipeline: whole runs over many objects (floor 4 of :mod:`dataset_gen`).

``parallel`` (one task per object on a process pool or Ray, resumable through io's manifest),
``generate`` (the generator), ``stats`` (dataset statistics), ``verify`` with
``verify_choices``, ``verify_contacts`` and ``verify_report`` (re-checking a release file),
``render`` (offscreen pictures of dual grasps).

May import: :mod:`dg16m_core`, the floors below and this folder.
"""
