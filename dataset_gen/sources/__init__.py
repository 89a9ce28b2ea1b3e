"""Sources: where objects come from (floor 3 of :mod:`dataset_gen`).

``object_source`` (an object named by a mesh file or a procedural ``(family, seed)``),
``procedural`` (the embedded object library), ``library`` (object folders written by
``dg16m objects make``).

May import: :mod:`dg16m_core`, the floors below (objects, io, force_closure, grasps) and this
folder.

Until 0.3.0, the names of the old module ``dataset_gen.sources`` (now
:mod:`dataset_gen.sources.object_source`) are found here with a :class:`DeprecationWarning`.
"""

from dataset_gen._compat import moved_names

__getattr__ = moved_names(__name__)
