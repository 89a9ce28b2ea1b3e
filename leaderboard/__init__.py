"""leaderboard: a results store, a command line, and an HTTP service that teams submit to.

* :mod:`leaderboard.board`: the board, one facade over its parts: :mod:`~leaderboard.store`
  (SQLite in WAL mode, connections, settings), :mod:`~leaderboard.teams` (teams and tokens),
  :mod:`~leaderboard.files` (submission files by content hash, uploads, orphans),
  :mod:`~leaderboard.queue` (scoring jobs with leases, events), :mod:`~leaderboard.results`
  (rows for the views) and :mod:`~leaderboard.checks` (errors, names, ids);
* :mod:`leaderboard.schema`: the database schema and its versioned migrations;
* :mod:`leaderboard.worker`: workers that claim jobs and score them with the registered
  evaluators (:mod:`dg16m_env.evaluators`);
* :mod:`leaderboard.views`: what the board shows (JSON-ready);
* :mod:`leaderboard.page`: the page (HTML, SVG charts, a small script for sorting), served or
  exported as static files, with its HTML helpers (:mod:`~leaderboard.page_html`) and its chart
  (:mod:`~leaderboard.page_chart`);
* :mod:`leaderboard.app`: the service (Starlette under uvicorn, with the request deadlines and
  limits of :mod:`leaderboard.protocol`); :mod:`leaderboard.client`: uploads over HTTP;
* :mod:`leaderboard.commands`: ``dg16m leaderboard ...``.

Submission files are HDF5 (:mod:`dg16m_env.subjects.submission`), validated before anything is stored
and never unpickled; the service never runs submitted code.
"""
