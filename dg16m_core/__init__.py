"""dg16m_core: the kernel every dg16m package may import.

What lives here is what the generator, the environments, the baselines and the leaderboard all
need and none of them owns:

=======================  =====================================================================
module                   what it holds
=======================  =====================================================================
``errors``               :class:`~dg16m_core.errors.Dg16mError` and the error vocabulary
``checks``               validation of scalar parameters, written once
``atomic``               atomic file writes (temporary file + rename)
``hashing``              content hashes of files
``json_values``          values made ready for strict JSON
``budget``               one object's work in a child process with a budget per stage
``stopping``             Ctrl-C and SIGTERM end a command and every process it started
``cli``                  the ``dg16m`` command line's plumbing (entry-point discovery, exits)
``arguments``            options many commands share (``--workers``/``--backend``/``--address``,
                         ``--no-progress``, ``--out``, ``--seed``, ``--limit``, id lists)
``distribution``         the installed distribution's name and version
``parameters``           the DG16M paper's parameters (``PAPER``), defined once
``figures``              matplotlib figures without pyplot, written as PNG
``progress``             progress bars: tqdm on a terminal, a plain line every few seconds in a log
``compat``               old import paths kept for one release (the mechanism; tables live in
                         each package's ``_compat``)
=======================  =====================================================================

May import: the standard library and third-party libraries, never a dg16m package
(``dataset_gen``, ``dg16m_env``, ``baselines``, ``leaderboard``); ``tests/test_import_circles.py``
keeps it so. Nothing here imports MuJoCo, torch, trimesh or h5py at module level.
"""
