"""Objects: meshes and what is measured on them (floor 0 of :mod:`dataset_gen`).

``grasp_object`` (load any mesh, clean, centre, scale, mass properties, convex parts),
``decomposition`` (CoACD convex parts, cached), ``mesh_queries`` (distances between a mesh and
its hulls), ``ray_hits`` (exact short-ray hits, compiled).

May import: :mod:`dg16m_core` and this folder.

Until 0.3.0, the names of the old module ``dataset_gen.objects`` (now
:mod:`dataset_gen.objects.grasp_object`) are found here with a :class:`DeprecationWarning`.
"""

from dataset_gen._compat import moved_names

__getattr__ = moved_names(__name__)
