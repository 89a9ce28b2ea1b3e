"""The subjects layer: what gets scored. Submission files (:mod:`.submission`: the format, its
limits and errors; :mod:`.submission_reader`: validation and reading, with the checks of the
file's attributes, tree and dataset headers in :mod:`.submission_structure`;
:mod:`.submission_writer`: writing), predictors given as code and run in a child process with
limits (:mod:`.predictor`, :mod:`.predictor_process`; on the cloud track, :mod:`.sandbox` keeps
them from the benchmark's files), and the observation a predictor sees of an object
(:mod:`.observation`; the cloud track's depth cameras, :mod:`.cloud_observation`; which track a
submission declares, :mod:`.track`).

Layer rule: modules here import :mod:`dg16m_env.benchmark`, :mod:`dg16m_env.physics` and
:mod:`dg16m_env.rates` (and :mod:`dataset_gen`), never the evaluators, envs or cli above them.
Where a submission is validated: :func:`.submission_reader.validate_submission`.
"""
