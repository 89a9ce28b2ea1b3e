"""Training data: a dataset folder (``dg16m dataset build``) as torch datasets.

:class:`~dg16m_env.training.grasp_dataset.DualGraspDataset` (map-style) and
:class:`~dg16m_env.training.grasp_dataset.DualGraspStream` (iterable, streams object files)
yield, per sample, one dual grasp with its labels and its object's cloud (a full surface
cloud, or the partial cloud of the cloud track's depth cameras).

Layer rule: above :mod:`dg16m_env.subjects` (whose cloud-track cameras it uses), below the
evaluators, envs and cli. Importing :mod:`~dg16m_env.training.grasp_dataset` needs torch (the
``learn`` extra); this package's ``__init__`` imports nothing.
"""
