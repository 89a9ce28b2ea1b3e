"""leaderboard: a results store, a command line, and an HTTP service that teams submit to.

* :mod:`leaderboard.board`: the store (SQLite in WAL mode, submission files by content hash),
  teams and tokens, the queue of scoring jobs with leases;
* :mod:`leaderboard.schema`: the database schema and its versioned migrations;
* :mod:`leaderboard.worker`: workers that claim jobs and score them with the registered
  evaluators (:mod:`dg16m_env.evaluators`);
* :mod:`leaderboard.views`: what the board shows (JSON-ready);
* :mod:`leaderboard.page`: the page (HTML, SVG charts, a small script for sorting), served or
  exported as static files;
* :mod:`leaderboard.app`: the service (Starlette under uvicorn); :mod:`leaderboard.client`:
  uploads over HTTP;
* :mod:`leaderboard.commands`: ``dg16m leaderboard ...``.

Submission files are HDF5 (:mod:`dg16m_env.submission`), validated before anything is stored
and never unpickled; the service never runs submitted code.
"""
