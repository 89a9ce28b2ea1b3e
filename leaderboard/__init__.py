"""leaderboard: submission validation, scoring through registered evaluators, results store and
page. Submissions are HDF5 or JSON; nothing a user submits is ever unpickled."""
