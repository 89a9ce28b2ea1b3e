"""leaderboard: a results store, a command line, and an HTTP service that teams submit to.

* :mod:`leaderboard.board`: the board, one facade over its parts: :mod:`~leaderboard.store`
  (SQLite in WAL mode, connections, settings), :mod:`~leaderboard.teams` (teams and tokens),
  :mod:`~leaderboard.files` (submission files by content hash, uploads, orphans),
  :mod:`~leaderboard.queue` (scoring jobs with leases, events), :mod:`~leaderboard.results`
  (rows for the views) and :mod:`~leaderboard.query_checks` (errors, names, ids, queries);
* :mod:`leaderboard.schema`: the database schema and its versioned migrations;
* :mod:`leaderboard.worker`: workers that claim jobs and score them with the registered
  evaluators (:mod:`dg16m_env.evaluators`);
* :mod:`leaderboard.views`: what the board shows (JSON-ready);
* :mod:`leaderboard.page`: the page (HTML, SVG charts, a small script for sorting), served or
  exported as static files, with its HTML helpers (:mod:`~leaderboard.page_html`) and its chart
  (:mod:`~leaderboard.page_chart`);
* :mod:`leaderboard.app`: the service (Starlette under uvicorn): a router per resource
  (:mod:`leaderboard.routes`), its limits (:mod:`~leaderboard.limits`), its error answers
  (:mod:`~leaderboard.http_errors`) and the request deadlines and limits of its connections
  (:mod:`~leaderboard.connections`); :mod:`leaderboard.client`: uploads over HTTP;
* :mod:`leaderboard.commands`: ``dg16m leaderboard ...``.

Submission files are HDF5 (:mod:`dg16m_env.subjects.submission`), validated before anything is stored
and never unpickled; the service never runs submitted code.

What may import what: the store's modules (``store``, ``teams``, ``files``, ``queue``,
``results``, ``query_checks``, ``schema``, ``board``) import no service module; ``views`` and
``page`` read the board; ``routes`` import those and Starlette; ``app`` wires ``routes`` and
``connections`` under uvicorn; ``commands`` imports the rest inside its handlers.

Modules renamed in 0.2.0 keep their old names for one release (``leaderboard._compat``:
``leaderboard.checks``, ``leaderboard.protocol``), with a :class:`DeprecationWarning`.
"""

from leaderboard import _compat

_compat.install()  # the old module names (leaderboard.checks, ...) for one release
