"""A dataset at DG16M's scale: objects from every open source, object-level splits, one build.

:mod:`~dataset_gen.collection.recipe` says what a dataset is made of (how many objects, from
which sources, the validation share and the seeds); :mod:`~dataset_gen.collection.splits`
assigns each object to ``train`` or ``validation`` and checks, by a hash of the geometry, that
no object is also in a benchmark; :mod:`~dataset_gen.collection.sources` turns the procedural
families, Sweet Home 3D's furniture and (optionally) pybullet's ``random_urdfs`` into items;
:mod:`~dataset_gen.collection.build` runs the generator over them (resumable, local processes
or Ray, the same bytes either way) and :mod:`~dataset_gen.collection.card` writes the card.

Floor 6 of :mod:`dataset_gen` (above :mod:`dataset_gen.real`, whose Sweet Home 3D import it
uses): it imports the kernel and every floor below it, never :mod:`dataset_gen.cli`. The
benchmarks the dataset must stay apart from are not read here (they live in the simulation
package above): the caller passes their hashes (:class:`~dataset_gen.collection.splits.Exclusion`).
"""
