"""dataset_gen: the offline DG16M generator (meshes in, dual grasps out).

Laid out in folders by what they do; a folder imports only from the kernel
(:mod:`dg16m_core`), its own folder and the folders below it (``tests/test_import_circles.py``
keeps it so). Nothing here imports MuJoCo or torch.

=====  ==================================  ====================================================
floor  folder                              what lives there
=====  ==================================  ====================================================
7      :mod:`dataset_gen.cli`              the generator's ``dg16m`` subcommands
6      :mod:`dataset_gen.collection`       a dataset at DG16M's scale: sources, splits, build,
                                           card
5      :mod:`dataset_gen.real`             real meshes: repair, your own folders, Sweet Home 3D,
                                           pybullet's random_urdfs
4      :mod:`dataset_gen.pipeline`         runs (pool, Ray, resume), generate, stats, verify,
                                           render
3      :mod:`dataset_gen.sources`          where objects come from: sources, procedural
                                           library, object folders
2      :mod:`dataset_gen.grasps`           gripper, sampling, clearance, pairing, selection,
                                           the robust criterion
1      :mod:`dataset_gen.io`,              the release schema, ACRONYM files, manifests; the
       :mod:`dataset_gen.force_closure`    force-closure check
0      :mod:`dataset_gen.objects`          meshes, convex decomposition, mesh queries, ray hits
=====  ==================================  ====================================================

Modules that moved in 0.2.0 keep their old names for one release (``dataset_gen._compat``:
``import dataset_gen.gripper`` still works and warns; the kernel's modules, such as
``dataset_gen.errors``, are in :mod:`dg16m_core`).
"""

from dataset_gen import _compat

_compat.install()  # the old module names (dataset_gen.grasps.gripper, ...) for one release
