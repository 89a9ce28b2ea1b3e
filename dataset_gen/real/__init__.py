"""Real meshes: repair and import (floor 5 of :mod:`dataset_gen`).

``repair`` (one watertight volume with a face budget, and what that moved), ``orientation``
(a source's up axis and the one turn to z up), ``own_meshes``
(your loose mesh files made into a mesh folder: ``dg16m objects repair``), ``sweethome3d``
(Debian's furniture libraries: catalogue, filter, import).

May import: :mod:`dg16m_core`, the floors below (they run on :mod:`dataset_gen.pipeline`'s
``parallel``) and this folder.
"""
