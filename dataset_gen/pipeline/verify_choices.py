"""Face choices at ambiguous contacts, for :mod:`dataset_gen.pipeline.verify`.

``_Verifier`` holds one verification's shared state (the file, the faces under its contacts, the
stored labels, the solver settings) and the checks of a recomputation against the stored
verdicts and losses; it enumerates alternative faces at the ambiguous contacts of disagreeing
pairs (fewest changed contacts first, ``_choice_positions``) and propagates the reproducing
choices to one face per contact point (``_Verifier.propagate``).
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from dataset_gen import io
from dataset_gen.force_closure import evaluate, project_cone_ball
from dataset_gen.pipeline.verify_contacts import BoolArray, ContactGeometry, FloatArray, IntArray

#: Absolute slack of the loss comparison (N), added to ``loss_rtol * stored``.
LOSS_ATOL = 1e-6
#: At most this many alternative face choices are evaluated per round over the whole file.
MAX_TOTAL_COMBINATIONS = 200_000
#: A stored force "sits in its cone" when it is within this distance (N) of the cone-ball.
CONE_TOLERANCE_N = 1e-4


# --------------------------------------------------------------------------------------------
# Face-choice enumeration
# --------------------------------------------------------------------------------------------


def _choice_positions(sizes: list[int], cap: int) -> Iterator[tuple[int, ...]]:
    """Positions into each contact's option list, all-zero excluded, fewest non-zero first."""
    varying = [k for k, s in enumerate(sizes) if s > 1]
    produced = 0
    for count in range(1, len(varying) + 1):
        for subset in itertools.combinations(varying, count):
            for picks in itertools.product(*(range(1, sizes[k]) for k in subset)):
                if produced >= cap:
                    return
                choice = [0] * len(sizes)
                for k, pick in zip(subset, picks, strict=True):
                    choice[k] = pick
                produced += 1
                yield tuple(choice)


@dataclass
class _Enumeration:
    """Reproducing face choices of a batch of pairs (choices are option indices per contact)."""

    matches: dict[int, list[tuple[int, ...]]]
    first: dict[int, tuple[tuple[int, ...], float]]  # pair -> (choice, loss) of the best match
    searched: dict[int, tuple[int, int]]  # pair -> (evaluated, possible)


class _Verifier:
    """Shared state of one verification (file, mesh geometry, stored labels, evaluate settings)."""

    def __init__(
        self,
        data: io.DualGraspSet,
        geometry: ContactGeometry,
        face_normals: FloatArray,
        fc_kwargs: dict[str, Any],
        loss_rtol: float,
        progress: bool,
    ) -> None:
        self.data = data
        self.geo = geometry
        self.face_normals = face_normals
        self.fc_kwargs = fc_kwargs
        self.loss_rtol = loss_rtol
        self.progress = progress
        n = data.n
        self.stored_pass = np.zeros(n, dtype=bool)
        self.stored_pass[data.passing_indices] = True
        self.labelled = self.stored_pass.copy()
        self.labelled[data.failed_indices] = True
        self.point_of = geometry.inverse.reshape(n, 4)

    def normals_for(self, choice: dict[int, int] | None = None) -> FloatArray:
        """``(N, 4, 3)`` mesh normals with the primary face, or ``choice[point]`` option index."""
        faces = self.geo.primary.copy()
        for u, pos in (choice or {}).items():
            faces[u] = self.geo.options[u][pos]
        return self.face_normals[faces[self.point_of]]

    def cone_violation(self, pairs: IntArray, normals: FloatArray) -> FloatArray:
        """``(len(pairs),)`` largest distance (N) of a stored force from its friction cone-ball."""
        forces = self.data.contact_forces[pairs]
        axes = normals if self.fc_kwargs["convention"] == "release" else -normals
        projected = project_cone_ball(forces, axes, self.fc_kwargs["mu"], self.fc_kwargs["f_high"])
        return np.linalg.norm(forces - projected, axis=-1).max(axis=1)

    def loss_matches(self, loss: FloatArray, pairs: IntArray) -> BoolArray:
        stored = self.data.loss_values[pairs]
        with np.errstate(invalid="ignore"):
            close = np.abs(loss - stored) <= self.loss_rtol * stored + LOSS_ATOL
        return np.where(np.isnan(loss), False, close)

    def reproduces(self, passed: BoolArray, loss: FloatArray, pairs: IntArray) -> BoolArray:
        """Whether (passed, loss) reproduce the stored verdict (and loss of stored failures)."""
        stored = self.stored_pass[pairs]
        return (passed == stored) & (stored | self.loss_matches(loss, pairs))

    def disagreeing(self, passed: BoolArray, loss: FloatArray) -> IntArray:
        everything = np.arange(self.data.n)
        ok = self.reproduces(passed, loss, everything)
        return np.flatnonzero(self.labelled & ~ok)

    def enumerate(
        self, pairs: IntArray, fixed: dict[int, int], max_per_pair: int
    ) -> tuple[_Enumeration, int]:
        """Evaluate alternative faces at the unfixed ambiguous contacts of ``pairs`` in one batch.

        At most ``max_per_pair`` choices per pair, fewer when the batch would exceed
        :data:`MAX_TOTAL_COMBINATIONS` (but at least 15, every choice of four two-faced contacts).
        Returns the reproducing choices and the number of choices evaluated.
        """
        found = _Enumeration({}, {}, {})
        rows: list[int] = []
        faces: list[list[int]] = []
        choices: list[tuple[int, ...]] = []
        plans = []
        for i in pairs:
            opts = []
            for u in self.point_of[i]:
                u = int(u)
                all_opts = self.geo.options[u]
                if u in fixed or len(all_opts) == 1:
                    base = fixed.get(u, 0)
                    opts.append([base])
                else:
                    opts.append(list(range(len(all_opts))))
            sizes = [len(o) for o in opts]
            if max(sizes) > 1:
                plans.append((int(i), opts, sizes))
        cap = min(max_per_pair, max(15, MAX_TOTAL_COMBINATIONS // max(len(plans), 1)))
        for i, opts, sizes in plans:
            possible = int(np.prod(sizes)) - 1
            evaluated = 0
            for pos in _choice_positions(sizes, cap):
                choice = tuple(opts[k][p] for k, p in enumerate(pos))
                points = self.point_of[i]
                # the same point twice in a pair must get the same face
                if any(
                    choice[a] != choice[b]
                    for a in range(4)
                    for b in range(a + 1, 4)
                    if points[a] == points[b]
                ):
                    continue
                rows.append(i)
                choices.append(choice)
                faces.append([self.geo.options[int(points[k])][choice[k]] for k in range(4)])
                evaluated += 1
            found.searched[i] = (evaluated, possible)
        if not rows:
            return found, 0
        row_arr = np.asarray(rows, dtype=np.int64)
        normals = self.face_normals[np.asarray(faces, dtype=np.int64)]
        result = evaluate(
            self.data.contact_points[row_arr],
            normals,
            progress=self.progress,
            **self.fc_kwargs,
        )
        ok = self.reproduces(result.passed, result.loss, row_arr)
        gap = np.abs(result.loss - self.data.loss_values[row_arr])
        outside = self.cone_violation(row_arr, normals) > CONE_TOLERANCE_N
        ranked: dict[int, list[tuple[bool, float, int]]] = {}
        for j in np.flatnonzero(ok):
            # choices whose cones hold the stored forces first; then for stored failures the
            # loss closest to the stored one; then enumeration order (fewest changes first)
            score = 0.0 if self.stored_pass[rows[j]] else float(gap[j])
            ranked.setdefault(rows[j], []).append((bool(outside[j]), score, int(j)))
        for i, entries in ranked.items():
            entries.sort()
            found.matches[i] = [choices[j] for _, _, j in entries]
            best = entries[0][2]
            found.first[i] = (choices[best], float(result.loss[best]))
        return found, len(rows)

    def _live(
        self, i: int, matches: dict[int, list[tuple[int, ...]]], fixed: dict[int, int]
    ) -> list[tuple[int, ...]]:
        points = [int(u) for u in self.point_of[i]]
        return [
            c for c in matches[i] if all(fixed.get(u, c[k]) == c[k] for k, u in enumerate(points))
        ]

    def _open_points(self, i: int, fixed: dict[int, int]) -> list[int]:
        return [
            k
            for k, u in enumerate(self.point_of[i])
            if int(u) not in fixed and len(self.geo.options[int(u)]) > 1
        ]

    def propagate(
        self, matches: dict[int, list[tuple[int, ...]]], fixed: dict[int, int]
    ) -> tuple[int, int]:
        """Choose one face per point so that every pair in ``matches`` keeps a reproducing choice.

        Deduction first: a point is fixed when all of a pair's remaining reproducing choices
        agree on it. When that stalls, the pair with the fewest remaining choices takes its best
        one (a guess) and deduction resumes. Pairs left without a consistent choice are skipped
        (they show up as disagreements when the file is re-evaluated).

        Returns:
            (points fixed by deduction, points fixed by a guess).
        """
        deduced = guessed = 0
        while True:
            changed = True
            while changed:
                changed = False
                for i in sorted(matches):
                    live = self._live(i, matches, fixed)
                    if not live:
                        continue
                    for k in self._open_points(i, fixed):
                        values = {c[k] for c in live}
                        if len(values) == 1:
                            fixed[int(self.point_of[i, k])] = values.pop()
                            deduced += 1
                            changed = True
            open_pairs = []
            for i in sorted(matches):
                live = self._live(i, matches, fixed)
                if live and self._open_points(i, fixed):
                    open_pairs.append((len(live), i, live[0]))
            if not open_pairs:
                return deduced, guessed
            _, i, choice = min(open_pairs)
            for k in self._open_points(i, fixed):
                fixed[int(self.point_of[i, k])] = choice[k]
                guessed += 1


__all__ = [
    "CONE_TOLERANCE_N",
    "LOSS_ATOL",
    "MAX_TOTAL_COMBINATIONS",
]
