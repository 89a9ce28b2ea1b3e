"""DA2-style dual-grasp labels (Zhai et al., "DA2 Dataset: Toward Dexterity-Aware Dual-Arm
Grasping", RA-L 2022) on the same four contacts as our force-closure check, and the data of the
paper's Fig. 4 (Q(G) separates passing from failing pairs in DG16M but not in DA2).

What DA2's code does (github.com/ymxlzgy/DA2, commit 917c2e2)
------------------------------------------------------------
``dexnet/grasping/force_closure_detection.py``, class ``FCLoss``:

* ``x_to_G`` (lines 28-38): for B pairs of N = 4 contact points ``x`` (B, 4, 3) it builds
  ``G`` (B, **6 x 3N = 6 x 12**): per contact the 6x3 block ``[I_3; [x_i]x]`` where ``[x]x`` is
  the cross-product matrix (``[x]x v = x x v``; the constant ``transformation_matrix`` of line
  10 maps ``x`` to ``[[0,-z,y],[z,0,-x],[-y,x,0]]`` row by row). Points are used as given: no
  centring, no scaling, no normalisation inside ``FCLoss``; torques are about the origin of the
  frame the points are in.
* ``loss_8a`` (lines 40-50): eigenvalues of the 6x6 matrix ``G G^T - eps I`` (``torch.symeig``;
  **G G^T**, not the 12x12 ``G^T G``), ``eps = 0.01`` (line 14);
  ``l8a = sum_i relu(-(lambda_i - eps))^2 = sum_i relu(eps - lambda_i(G G^T))^2``.
* ``loss_8b`` (lines 52-59): ``l8b = ||G f||^2`` with ``f`` (B, 4, 3) flattened to 12: the
  squared norm of the net wrench (force and torque about the origin) of one unit force per
  contact along the vector passed as ``normal``. ``loss_8c`` (friction) is commented out in
  ``fc_loss`` (line 82): the criterion is frictionless and the forces have equal magnitudes.

``dexnet/grasping/quality.py``, ``PointGraspMetrics3D.Dual_force_closure_batch`` (lines 316-344):
``result1 = where(l8a < 0.01, l8a, 0)``, ``result2 = where(l8b < 1, l8b, 0)`` (comments "0 is not
qualified"), returns ``(result1 * result2, result2)``.

``dexnet/grasping/grasp_sampler.py``, ``GraspSampler.generate_grasps`` (lines 224-390): the mesh
is translated by ``-mesh.centroid`` (trimesh's area-weighted surface centroid, line 275) and, only
when its largest bounding-box side exceeds 1 m, scaled by a random factor putting that side in
[0.6, 1.0] m (lines 268-276); ``MeshAntipodalGraspSampler.multi_grasp`` (lines 733-858) takes
contacts from surface samples with ``mesh.face_normals`` (outward unit face normals, line 762),
the second contact being the surface sample nearest the ray hit (line 786), so DA2's own contacts
are generically not exactly antipodal. The call is
``Dual_force_closure_batch(grasp_points, -grasp_normals)`` (line 327: **inward** normals), a
pair is kept when ``a_array * 1e3 != 0`` (line 328) and its stored ``qualities/Force_closure`` is
``1 - result2`` = ``1 - l8b`` (line 330; ``scripts/generate_dual_dataset.py`` line 48).

What this module implements
---------------------------
:func:`da2_criterion`, for (N, 4, 3) contacts ``p`` (m) and unit normals:

* ``H = G G^T`` with ``G = [I I I I; [q_1]x .. [q_4]x]`` (6 x 12), ``q_i = p_i - center``
  (``center`` defaults to the frame origin; in dg16m files and the benchmark that origin is the
  trimesh surface centroid, DA2's origin). ``H`` is :func:`dataset_gen.force_closure.gram_matrix`
  of ``q``, because our paper's G (``[R_k; [p_k]x R_k]``) has the same ``G G^T`` as DA2's.
* ``l8a = sum_i relu(-eigvalsh(H - eps I))_i^2`` (the order of DA2's arithmetic).
* ``l8b = ||sum_i f_i||^2 + ||sum_i q_i x f_i||^2`` with ``f_i`` the inward unit normal, which
  equals ``||G f||^2``.
* ``passed = (where(l8a < 0.01, l8a, 0) * where(l8b < 1, l8b, 0)) * 1e3 != 0``, DA2's expression
  verbatim (so NaN fails, and a product that underflows to 0 fails as in DA2). For finite inputs
  this is ``0 < l8a < 0.01 and 0 < l8b < 1``. Option ``zero_tol`` (default 0, verbatim) counts
  values ``<= zero_tol`` as DA2's 0 (see below).
* ``quality = 1 - l8b`` for every pair (DA2 stores it only for kept pairs, where it is in (0, 1)).

Consequences of DA2's definition (documented, tested, kept as DA2 has them)
---------------------------------------------------------------------------
* **The l8a test is one-sided the wrong way.** ``G G^T`` is positive semi-definite, so every term
  of l8a is at most ``eps^2`` and ``l8a <= 6 eps^2 = 6e-4 < 0.01``: the upper threshold never
  rejects anything. The only effective condition is ``l8a > 0``, i.e. **the smallest eigenvalue of
  G G^T is below eps = 0.01 m^2**; a well-conditioned pair (all eigenvalues >= 0.01, l8a == 0
  exactly) is rejected, and a fully degenerate one (all contacts at one point, rank 3) can pass.
* **For dual parallel-jaw grasps the l8a test is vacuous in both directions.** With ``u`` the
  direction of the line joining the two grasp centres (it passes through the contacts' centroid)
  and ``d_i`` the distance of contact i from that line: ``v^T G G^T v = sum_i |x + y x q_i|^2``,
  so at ``v = (m x u, u)`` (``m`` the contacts' centroid, |v| >= 1)
  ``lambda_min(G G^T) <= sum_i d_i^2 <= (w_0^2 + w_1^2) / 2 <= w^2`` for contact separations
  ``w_k <= w``, about any ``center``. The Panda hand opens 0.08 m (6.4e-3 < eps), so every dual
  Panda grasp has ``0 < l8a < 0.01`` (measured: no exception in the 30,000 benchmark pairs and
  74k generated pairs). DA2's verdict is then ``0 < l8b < 1``.
* **l8b == 0 is rejected as well**: four exactly balanced unit forces fail. Our procedural
  objects are built from flat-faced primitives and their contacts come from closing the jaws, so
  about half the pairs are exactly antipodal on both arms: their l8b is 0 or float64 rounding
  (1e-36..1e-24), and a further ~10% sit on faces parallel up to float32 vertex precision
  (1e-18..1e-10). With the verbatim rule those pairs pass or fail with the rounding of the
  summation (numpy here, cuBLAS in DA2: the two need not agree; computing l8b as DA2's 6x12
  product ``G @ f`` in numpy instead of our net force and torque flips 413 of the benchmark's
  30,000 verdicts); ``zero_tol=GEOMETRIC_ZERO``
  rejects them all, deterministically. And l8b < 1 held for every pair measured, so DA2's rule
  on dg16m data is "the net wrench of the unit normals is not (numerically) zero".
* **Normals' sign is irrelevant**: l8a does not use normals and ``||G(-f)|| = ||G f||``, so
  ``normals="outward"`` and ``"inward"`` give identical results (we still flip outward normals to
  DA2's inward convention).
* **Not frictionless force closure** in the usual sense: nothing tests that the contact wrenches
  positively span R^6 (impossible anyway with four frictionless contacts, which need at least
  seven). l8a measures the conditioning of the contact geometry, l8b the balance of one fixed
  force set.
* **Units and frame matter.** ``eps`` compares with eigenvalues whose torque part scales as
  length^2 (m^2), so for general contacts the verdict changes with the object's size (not for
  dual parallel-jaw grasps, by the bound above); and the eigenvalues of
  ``G G^T`` (and l8b, unless the forces sum to zero) change when the torque reference point
  moves: the verdict is **not translation invariant**, only invariant when points and
  ``center`` move together (and invariant under rotations about ``center``).

Deviations from DA2
-------------------
* numpy ``eigvalsh`` (LAPACK, lower triangle) replaces ``torch.symeig`` (upper triangle) on the
  GPU: identical up to rounding (a pair exactly at a threshold may differ).
* l8b is computed as net force and torque rather than a 6x12 matrix product: equal up to rounding.
* No rescaling: DA2 rescales objects larger than 1 m to a random 0.6-1.0 m; we evaluate the
  contacts in the file's metres (objects up to 1 m are what DA2 would see; larger ones are not).
  It does not change the verdicts beyond rounding: the l8a bound above holds at any scale, and
  scaling by s <= 1 maps l8b to a value between s^2 l8b and l8b (0 stays 0, < 1 stays < 1).
* ``zero_tol`` is ours (default 0: DA2's literal rule).
* Only the keep rule is reproduced. DA2's pairing (dexnet ``array_distance > 0.05`` on grasp
  centres and axes, no gripper-gripper collision check), its sampler and its final truncation to
  ``target_num_grasps`` by thirds of the quality are not: we label the same candidate pairs our
  generator and benchmark produce, so only the criterion differs.
* Inputs are validated once (shapes, finite values, unit normals): DA2 checks nothing.

Measured on the shipped benchmark (30,000 candidate pairs, 300 objects; verbatim rule)
--------------------------------------------------------------------------------------
DA2 passes 52.5% (ours 46.9%); agreement 47.1%, Cohen's kappa -0.05. Mean success probability
(all disturbances) of DA2-passing pairs 0.43 vs DA2-failing 0.46 (ours: 0.70 vs 0.21); ROC AUC
for the binary success label: our verdict 0.75, DA2's 0.49; Q(G) 0.68, ``1 - l8b`` 0.52. Q(G)
predicting our verdict: AUC 0.62, predicting DA2's: 0.50. With ``zero_tol=GEOMETRIC_ZERO`` DA2
passes 14.2%, kappa 0.02, success 0.47 vs 0.44 (AUC 0.51).

Fig. 4 and the comparison: :func:`quality_separation` (per-class statistics and the rank ROC
AUC of a quality predicting a verdict), :func:`agreement` (2x2 table, agreement rate, Cohen's
kappa), :func:`compare_labels` (both at once, plus simulated success per verdict) and
:func:`fig4_figure` (two histogram panels, built on :class:`matplotlib.figure.Figure`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal, get_args

import numpy as np
from matplotlib.figure import Figure

from baselines.pairing_baselines import BaselineError
from dataset_gen.force_closure.geometry import gram_matrix
from dataset_gen.io import DualGraspSet
from dg16m_core.checks import check_number

NormalConvention = Literal["outward", "inward"]
NORMAL_CONVENTIONS: tuple[str, ...] = get_args(NormalConvention)

EPS = 0.01
"""``FCLoss.eps`` (force_closure_detection.py line 14): eigenvalue floor of G G^T (m^2 units)."""

L8A_MAX = 0.01
"""``Dual_force_closure_batch``: l8a must be below this (and non-zero)."""

L8B_MAX = 1.0
"""``Dual_force_closure_batch``: l8b must be below this (and non-zero)."""

GEOMETRIC_ZERO = 1e-8
"""A ``zero_tol`` for :func:`da2_criterion` that counts a net wrench below 1e-4 (unit forces; N
and N m) as zero: above float64 rounding (l8b ~ 1e-36..1e-24) and the float32 precision of mesh
vertices (opposite faces parallel to ~1e-6: l8b ~ 1e-18..1e-10), below every geometric
imbalance measured on dg16m data (l8b >= 1e-6, with almost nothing in 1e-10..1e-6)."""

UNIT_TOL = 1e-6
"""Largest accepted deviation of a normal's length from 1."""

QUANTILES = (0.05, 0.25, 0.5, 0.75, 0.95)
"""Quantiles reported by :func:`quality_separation`."""

N_CONTACTS = 4


class DA2LabelError(BaselineError):
    """Malformed input to the DA2 criterion or to the Fig. 4 statistics."""


@dataclass(frozen=True)
class DA2Result:
    """DA2's losses, keep rule and stored quality for N dual grasps.

    Attributes:
        l8a: (N,) float64 ``sum_i relu(eps - lambda_i(G G^T))^2`` (m^4).
        l8b: (N,) float64 ``||G f||^2``, squared net wrench of unit inward normal forces.
        passed: (N,) bool DA2's keep rule (``0 < l8a < 0.01`` and ``0 < l8b < 1``).
        quality: (N,) float64 ``1 - l8b`` (DA2's ``qualities/Force_closure``).
    """

    l8a: np.ndarray
    l8b: np.ndarray
    passed: np.ndarray
    quality: np.ndarray

    @property
    def n(self) -> int:
        return int(self.l8a.size)


def _contacts(name: str, value: Any) -> np.ndarray:
    """``value`` as a finite (N, 4, 3) float64 array, else :class:`DA2LabelError`."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise DA2LabelError(
            f"{name}: expected a numeric (N, 4, 3) array, found {type(value).__name__}"
        ) from None
    if arr.ndim != 3 or arr.shape[1:] != (N_CONTACTS, 3):
        raise DA2LabelError(f"{name}: expected shape (N, 4, 3), found {arr.shape}")
    bad = ~np.isfinite(arr).all(axis=(1, 2))
    if bad.any():
        raise DA2LabelError(
            f"{name}: expected finite values, found NaN/inf in {int(bad.sum())} pair(s), "
            f"first at pair {int(np.flatnonzero(bad)[0])}"
        )
    return arr


def da2_criterion(
    contact_points: np.ndarray,
    contact_normals: np.ndarray,
    *,
    eps: float = EPS,
    normals: NormalConvention = "outward",
    center: np.ndarray | Sequence[float] | None = None,
    zero_tol: float = 0.0,
) -> DA2Result:
    """DA2's frictionless dual-grasp criterion (``FCLoss`` + ``Dual_force_closure_batch``).

    Args:
        contact_points: (N, 4, 3) contacts in the object frame (m); rows 0, 1 arm 0, rows 2, 3
            arm 1 (the order does not matter to the criterion).
        contact_normals: (N, 4, 3) unit surface normals at the contacts.
        eps: the eigenvalue floor of ``G G^T`` (DA2: 0.01).
        normals: ``"outward"`` (dg16m files and the benchmark store outward face normals; they
            are flipped to DA2's inward forces) or ``"inward"``. The result does not depend on
            it (see the module docstring); it is validated for clarity.
        center: (3,) point the torques are taken about (m); default the frame origin, which in
            dg16m data is the trimesh surface centroid, DA2's choice.
        zero_tol: l8a or l8b at or below this count as DA2's "0 is not qualified" (default 0.0:
            DA2's expression verbatim, where an exactly balanced pair passes or fails with the
            rounding of its net wrench; :data:`GEOMETRIC_ZERO` makes the verdict independent of
            rounding and of mesh-vertex precision). ``zero_tol`` must stay below
            ``min(L8A_MAX, L8B_MAX)``.

    Returns:
        :class:`DA2Result` with (N,) arrays.

    Raises:
        DA2LabelError: wrong shapes, non-finite values, non-unit normals, bad ``eps``,
            ``normals`` or ``center``.
    """
    points = _contacts("contact_points", contact_points)
    forces = _contacts("contact_normals", contact_normals)
    if forces.shape != points.shape:
        raise DA2LabelError(
            f"contact_normals: expected the shape of contact_points {points.shape}, "
            f"found {forces.shape}"
        )
    lengths = np.linalg.norm(forces, axis=-1)
    off = np.abs(lengths - 1.0) > UNIT_TOL
    if off.any():
        i, k = np.argwhere(off)[0]
        raise DA2LabelError(
            f"contact_normals: expected unit vectors (| |n| - 1 | <= {UNIT_TOL:g}), found "
            f"|n| = {lengths[i, k]:.6g} at pair {i} contact {k} ({int(off.sum())} in all)"
        )
    eps = check_number("eps", eps, error=DA2LabelError)
    zero_tol = check_number("zero_tol", zero_tol, allow_zero=True, error=DA2LabelError)
    if zero_tol >= min(L8A_MAX, L8B_MAX):
        raise DA2LabelError(
            f"zero_tol: expected a value below {min(L8A_MAX, L8B_MAX):g}, found {zero_tol!r}"
        )
    if normals not in NORMAL_CONVENTIONS:
        raise DA2LabelError(f"normals: expected one of {NORMAL_CONVENTIONS}, found {normals!r}")
    if center is not None:
        c = np.asarray(center, dtype=np.float64)
        if c.shape != (3,) or not np.isfinite(c).all():
            raise DA2LabelError(f"center: expected a finite (3,) point, found {c!r}")
        points = points - c
    if normals == "outward":
        forces = -forces  # DA2 pushes along the inward normal (grasp_sampler.py line 327)
    n = points.shape[0]
    if n == 0:
        empty = np.zeros(0)
        return DA2Result(empty, empty.copy(), np.zeros(0, dtype=bool), empty.copy())

    H = gram_matrix(points)  # (N, 6, 6) = G G^T, G = [I ..; [q_i]x ..] (6 x 12)
    shifted = np.linalg.eigvalsh(H - eps * np.eye(6))  # FCLoss.loss_8a: eig(G G^T - eps I)
    rnev = np.maximum(-shifted, 0.0)
    l8a = np.sum(rnev * rnev, axis=1)

    net_force = forces.sum(axis=1)  # (N, 3)
    net_torque = np.cross(points, forces).sum(axis=1)  # (N, 3), about ``center``
    l8b = np.sum(net_force * net_force, axis=1) + np.sum(net_torque * net_torque, axis=1)

    # Dual_force_closure_batch (quality.py 337-344) and the keep test (grasp_sampler.py 328).
    with np.errstate(invalid="ignore", under="ignore"):
        result1 = np.where((l8a < L8A_MAX) & (l8a > zero_tol), l8a, 0.0)
        result2 = np.where((l8b < L8B_MAX) & (l8b > zero_tol), l8b, 0.0)
        passed = (result1 * result2) * 1e3 != 0
    return DA2Result(l8a=l8a, l8b=l8b, passed=passed, quality=1.0 - l8b)


def da2_labels_for_file(data: DualGraspSet, **kwargs: Any) -> DA2Result:
    """DA2's criterion on every pair of one dg16m grasp file (:func:`dataset_gen.io.read_dg16m`).

    Uses ``data.contact_points`` (N, 4, 3) and ``data.extras["contact_normals"]`` (N, 4, 3,
    outward); ``kwargs`` go to :func:`da2_criterion` (``normals`` defaults to ``"outward"``).

    Raises:
        DA2LabelError: the file has no contact normals (files of the original DG16M release do
            not store them), or they are malformed.
    """
    normals = data.extras.get("contact_normals")
    if normals is None:
        raise DA2LabelError(
            f"{data.object_file}: expected extras['contact_normals'] (N, 4, 3) outward normals "
            "(written by `dg16m generate`), found none (DG16M release files have no normals)"
        )
    return da2_criterion(data.contact_points, normals, **kwargs)


def dg16m_passed(data: DualGraspSet) -> np.ndarray:
    """(N,) bool: our force-closure verdict of each row (True at ``passing_indices``).

    Raises:
        DA2LabelError: a row is in neither ``passing_indices`` nor ``failed_indices``.
    """
    n = data.contact_points.shape[0]
    passed = np.zeros(n, dtype=bool)
    passed[data.passing_indices] = True
    known = passed.copy()
    known[data.failed_indices] = True
    if not known.all():
        raise DA2LabelError(
            f"{data.object_file}: expected every row in fc_passing_indices or fc_failed_indices, "
            f"found {int((~known).sum())} row(s) in neither"
        )
    return passed


def _verdicts(name: str, value: Any, n: int | None = None) -> np.ndarray:
    arr = np.asarray(value)
    if arr.ndim != 1 or (n is not None and arr.shape[0] != n):
        want = "(N,)" if n is None else f"({n},)"
        raise DA2LabelError(f"{name}: expected shape {want}, found {arr.shape}")
    if arr.dtype != bool:
        if arr.size and not np.isin(arr, (0, 1)).all():
            raise DA2LabelError(f"{name}: expected booleans (or 0/1), found dtype {arr.dtype}")
        arr = arr.astype(bool)
    return arr


def _scores(name: str, value: Any, n: int) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise DA2LabelError(f"{name}: expected a numeric ({n},) array") from None
    if arr.shape != (n,):
        raise DA2LabelError(f"{name}: expected shape ({n},), found {arr.shape}")
    if not np.isfinite(arr).all():
        raise DA2LabelError(
            f"{name}: expected finite values, found {int((~np.isfinite(arr)).sum())} NaN/inf"
        )
    return arr


def roc_auc(scores: np.ndarray, positive: np.ndarray) -> float | None:
    """Rank ROC AUC of ``scores`` (N,) predicting ``positive`` (N,) bool.

    The Mann-Whitney statistic with average ranks for ties (a tie counts half): 1.0 when every
    positive scores above every negative, 0.0 reversed, 0.5 for identical scores. None when a
    class is empty.
    """
    positive = _verdicts("positive", positive)
    scores = _scores("scores", scores, positive.size)
    n_pos = int(positive.sum())
    n_neg = positive.size - n_pos
    if n_pos == 0 or n_neg == 0:
        return None
    from scipy.stats import rankdata

    ranks = rankdata(scores)  # average ranks for ties
    return float((ranks[positive].sum() - n_pos * (n_pos + 1) / 2) / (n_pos * n_neg))


def _summary(values: np.ndarray) -> dict[str, Any]:
    if values.size == 0:
        return {"count": 0, "mean": None, "median": None, "quantiles": None}
    qs = np.quantile(values, QUANTILES)
    return {
        "count": int(values.size),
        "mean": float(values.mean()),
        "median": float(np.median(values)),
        "quantiles": {f"{q:g}": float(v) for q, v in zip(QUANTILES, qs, strict=True)},
    }


def quality_separation(quality: np.ndarray, passed: np.ndarray) -> dict[str, Any]:
    """How well a quality separates passing from failing pairs (JSON-ready).

    Args:
        quality: (N,) finite qualities (higher = better).
        passed: (N,) bool verdicts.

    Returns:
        ``{"n", "passed": {count, mean, median, quantiles}, "failed": {...}, "auc"}``; ``auc`` is
        :func:`roc_auc` of ``quality`` predicting ``passed`` (None when a class is empty);
        statistics of an empty class are None.
    """
    passed = _verdicts("passed", passed)
    quality = _scores("quality", quality, passed.size)
    return {
        "n": int(passed.size),
        "passed": _summary(quality[passed]),
        "failed": _summary(quality[~passed]),
        "auc": roc_auc(quality, passed),
    }


def agreement(ours_passed: np.ndarray, da2_passed: np.ndarray) -> dict[str, Any]:
    """2x2 table of two verdicts on the same pairs, agreement rate and Cohen's kappa (JSON-ready).

    Args:
        ours_passed: (N,) bool, our force-closure verdicts.
        da2_passed: (N,) bool, DA2's.

    Returns:
        ``{"n", "both_pass", "ours_only", "da2_only", "both_fail", "agreement", "kappa",
        "ours_pass_rate", "da2_pass_rate"}``; rates are None for N = 0 and kappa is None when
        chance agreement is 1 (both verdicts constant and equal).
    """
    ours = _verdicts("ours_passed", ours_passed)
    da2 = _verdicts("da2_passed", da2_passed, ours.size)
    n = ours.size
    table = {
        "both_pass": int((ours & da2).sum()),
        "ours_only": int((ours & ~da2).sum()),
        "da2_only": int((~ours & da2).sum()),
        "both_fail": int((~ours & ~da2).sum()),
    }
    out: dict[str, Any] = {"n": int(n), **table}
    if n == 0:
        return {
            **out,
            "agreement": None,
            "kappa": None,
            "ours_pass_rate": None,
            "da2_pass_rate": None,
        }
    po = (table["both_pass"] + table["both_fail"]) / n
    a, b = ours.mean(), da2.mean()
    pe = a * b + (1 - a) * (1 - b)
    kappa = None if pe >= 1.0 else float((po - pe) / (1 - pe))
    return {
        **out,
        "agreement": float(po),
        "kappa": kappa,
        "ours_pass_rate": float(a),
        "da2_pass_rate": float(b),
    }


def _mean_or_none(values: np.ndarray) -> float | None:
    return float(values.mean()) if values.size else None


def compare_labels(
    ours_passed: np.ndarray,
    ours_quality: np.ndarray,
    da2: DA2Result,
    p: np.ndarray | None = None,
) -> dict[str, Any]:
    """Our verdicts and Q(G) against DA2's verdicts and quality on the same N pairs (JSON-ready).

    Args:
        ours_passed: (N,) bool, our force-closure verdicts.
        ours_quality: (N,) our Q(G) = sqrt(det(G G^T)).
        da2: :func:`da2_criterion` of the same pairs.
        p: optional (N,) simulated success probabilities.

    Returns:
        ``agreement`` (:func:`agreement`); ``ours`` / ``da2``: :func:`quality_separation` of each
        quality against its own verdict; ``cross``: AUC of Q(G) predicting DA2's verdict and of
        ``1 - l8b`` predicting ours; ``da2_rule``: how DA2's rule decides (counts of l8a == 0,
        l8b == 0, l8b >= 1); with ``p``: mean p per verdict, per cell of the 2x2 table, and
        the AUC of each quality predicting ``p >= 0.5``.
    """
    ours = _verdicts("ours_passed", ours_passed, da2.n)
    q_ours = _scores("ours_quality", ours_quality, da2.n)
    out: dict[str, Any] = {
        "agreement": agreement(ours, da2.passed),
        "ours": quality_separation(q_ours, ours),
        "da2": quality_separation(da2.quality, da2.passed),
        "cross": {
            "auc_ours_quality_for_da2_passed": roc_auc(q_ours, da2.passed),
            "auc_da2_quality_for_ours_passed": roc_auc(da2.quality, ours),
        },
        "da2_rule": {
            "l8a_zero": int((da2.l8a == 0).sum()),
            "l8b_zero": int((da2.l8b == 0).sum()),
            "l8b_at_least_1": int((da2.l8b >= L8B_MAX).sum()),
            "l8a_max": float(da2.l8a.max()) if da2.n else None,
        },
    }
    if p is not None:
        prob = _scores("p", p, da2.n)
        d = da2.passed
        out["p"] = {
            "all": _mean_or_none(prob),
            "ours_pass": _mean_or_none(prob[ours]),
            "ours_fail": _mean_or_none(prob[~ours]),
            "da2_pass": _mean_or_none(prob[d]),
            "da2_fail": _mean_or_none(prob[~d]),
            "both_pass": _mean_or_none(prob[ours & d]),
            "ours_only": _mean_or_none(prob[ours & ~d]),
            "da2_only": _mean_or_none(prob[~ours & d]),
            "both_fail": _mean_or_none(prob[~ours & ~d]),
            "auc_ours_quality_for_success": roc_auc(q_ours, prob >= 0.5),
            "auc_da2_quality_for_success": roc_auc(da2.quality, prob >= 0.5),
            "auc_ours_verdict_for_success": roc_auc(ours.astype(float), prob >= 0.5),
            "auc_da2_verdict_for_success": roc_auc(d.astype(float), prob >= 0.5),
        }
    return out


def _panel(ax: Any, quality: np.ndarray, passed: np.ndarray, title: str, xlabel: str, bins: int):
    auc = roc_auc(quality, passed)
    if quality.size:
        lo, hi = np.quantile(quality, (0.005, 0.995))
        if hi <= lo:
            lo, hi = lo - 0.5, hi + 0.5
        edges = np.linspace(lo, hi, bins + 1)
        for mask, label, color in (
            (passed, "passing", "tab:green"),
            (~passed, "failing", "tab:red"),
        ):
            if mask.any():
                ax.hist(
                    np.clip(quality[mask], lo, hi),
                    bins=edges,
                    density=True,
                    alpha=0.55,
                    color=color,
                    label=f"{label} (n={int(mask.sum())})",
                )
        ax.legend(loc="best", fontsize="small")
    auc_text = "n/a" if auc is None else f"{auc:.3f}"
    ax.set_title(f"{title}\nROC AUC = {auc_text}")
    ax.set_xlabel(f"{xlabel} (tails clipped to 0.5-99.5%)")
    ax.set_ylabel("density")


def fig4_figure(
    ours: tuple[np.ndarray, np.ndarray],
    da2: tuple[np.ndarray, np.ndarray],
    *,
    bins: int = 40,
    titles: tuple[str, str] = ("DG16M labels", "DA2 labels"),
    xlabels: tuple[str, str] = ("Q(G) = sqrt(det(G G^T))", "DA2 quality 1 - l8b"),
) -> Figure:
    """The paper's Fig. 4: histograms of the quality of passing vs failing pairs, two panels.

    Args:
        ours: ``(quality (N,), passed (N,))``, our Q(G) and force-closure verdicts.
        da2: ``(quality (M,), passed (M,))``, DA2's ``1 - l8b`` and keep rule.
        bins: histogram bins per panel.
        titles, xlabels: panel titles and x-axis labels.

    Returns:
        A :class:`matplotlib.figure.Figure` with two axes (no pyplot).
    """
    fig = Figure(figsize=(10.0, 4.0), layout="constrained")
    axes = fig.subplots(1, 2)
    for ax, (quality, passed), title, xlabel in zip(
        axes, (ours, da2), titles, xlabels, strict=True
    ):
        v = _verdicts("passed", passed)
        q = _scores("quality", quality, v.size)
        _panel(ax, q, v, title, xlabel, bins)
    return fig
