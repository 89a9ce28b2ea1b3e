"""Force-closure throughput: our methods against a CVXPY per-pair loop, in the same run.

Builds at least 50,000 four-contact pairs of mixed difficulty:

* real: single-arm contact pairs of the DG16M release's airplane file, re-paired at random into
  new dual grasps (normals = face normals of the faces the contacts lie on), when
  ``../shared/data/real`` is present;
* synthetic families from :mod:`dataset_gen.force_closure.synthetic` (antipodal on spheres,
  pinches on boxes, random, near-collinear);
* near-threshold: pairs moved along a straight path from a passing to a failing box pinch until
  their optimal loss hits a target drawn log-uniformly from ``[threshold / 3, 3 threshold]``
  (bisection on a tight Clarabel solve); the printed loss distribution shows what was reached.

Verdicts near the threshold are checked on that set and on a second one drawn the same way
within 1 % of the threshold (``[threshold / 1.01, 1.01 threshold]``, the stress case): every
method against a TIGHT reference (per pair the better of a default and a
:data:`~dataset_gen.force_closure.clarabel_solver.TIGHT_SETTINGS` Clarabel solve: lowest
attained loss, highest dual bound), beside a plain Clarabel solve at its default tolerances.
That is where default tolerances flip verdicts and where the library's tight re-solve of the
pairs whose bounds straddle the threshold earns its cost.

Then times, on one core: a CVXPY loop written like the released code (subsample), Clarabel on
every pair (the library's reference method), and ``fast`` / ``auto`` in exact-loss and
verdict-only modes. Prints pairs/s, the ratios to the CVXPY loop and to Clarabel measured in the
same run, the share sent to Clarabel, and verdict agreement with Clarabel on every pair.

    .venv/bin/python bench/fc_throughput.py            # about two minutes
    .venv/bin/python bench/fc_throughput.py --pairs 20000 --near-threshold 200   # short
    .venv/bin/python bench/fc_throughput.py --json runs/fc_throughput.json
"""

from __future__ import annotations

import os

# One core: no BLAS or numba threads (set before numpy is imported).
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse
import itertools
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dataset_gen.force_closure import SOLVED_CLARABEL_TIGHT, evaluate, grasp_matrix
from dataset_gen.force_closure.clarabel_solver import ClarabelBatch, best_of, solve_batch
from dataset_gen.force_closure.synthetic import FAMILIES, family_pairs
from dg16m_core.parameters import PAPER

REAL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"


@dataclass
class Arguments:
    pairs: int = 50_000
    cvxpy_pairs: int = 200
    near_threshold: int = 400
    convention: str = "physical"
    seed: int = 0
    json: str | None = None


def parse() -> Arguments:
    defaults = Arguments()
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pairs", type=int, default=defaults.pairs)
    parser.add_argument("--cvxpy-pairs", type=int, default=defaults.cvxpy_pairs)
    parser.add_argument("--near-threshold", type=int, default=defaults.near_threshold)
    parser.add_argument("--convention", choices=("physical", "release"), default="physical")
    parser.add_argument("--seed", type=int, default=defaults.seed)
    parser.add_argument("--json", default=None, help="also write the results here")
    return Arguments(**vars(parser.parse_args()))


def real_repaired(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray] | None:
    """Random re-pairings of the release airplane's single-arm contact pairs."""
    h5, obj = REAL / "dg16m_airplane.h5", REAL / "dg16m_airplane.obj"
    if not h5.is_file():
        return None
    import trimesh

    from dataset_gen.io import read_dg16m

    grasps = read_dg16m(h5)
    mesh = trimesh.load(obj, force="mesh")
    mesh.apply_scale(grasps.object_scale)
    mesh.apply_translation(-mesh.centroid)
    points = grasps.contact_points
    _, _, faces = mesh.nearest.on_surface(points.reshape(-1, 3))
    normals = mesh.face_normals[faces].reshape(points.shape)
    arm_points = np.concatenate([points[:, :2], points[:, 2:]])
    arm_normals = np.concatenate([normals[:, :2], normals[:, 2:]])
    a, b = rng.integers(0, len(arm_points), size=(2, n))
    return (
        np.concatenate([arm_points[a], arm_points[b]], axis=1),
        np.concatenate([arm_normals[a], arm_normals[b]], axis=1),
    )


def _axes(normals: np.ndarray, convention: str) -> np.ndarray:
    return -normals if convention == "physical" else normals


def _clarabel(
    points: np.ndarray, normals: np.ndarray, convention: str, *, tight: bool
) -> ClarabelBatch:
    """Plain Clarabel solves of the gravity problem (no re-solve), default or tight tolerances,
    on the same unit axes that :func:`evaluate` builds (it normalises the normals again)."""
    wrench = np.tile(PAPER.gravity_wrench(), (len(points), 1))
    unit = normals / np.linalg.norm(normals, axis=-1)[..., None]
    axes = _axes(unit, convention)
    return solve_batch(points, axes, wrench, mu=PAPER.mu, f_high=PAPER.f_high, tight=tight)


def near_threshold(
    n: int, rng: np.random.Generator, convention: str, spread: float = 3.0
) -> tuple[np.ndarray, np.ndarray]:
    """Pairs whose optimal loss is spread log-uniformly over [threshold / spread, spread
    threshold].

    Each pair lies on a straight path from a passing box pinch (loss 0) to a failing one (loss
    proven > 3 threshold); bisection on a tight Clarabel solve moves it to where the loss crosses
    its own target ``threshold * spread ** U(-1, 1)`` (the loss is continuous along the path).
    """
    threshold = PAPER.threshold
    points, normals = family_pairs("box", 20 * n, rng)
    result = evaluate(points, normals, convention=convention, loss_rtol=None)
    good = np.flatnonzero(result.passed)
    bad = np.flatnonzero(result.rank_ok & (result.loss_lower[:, 0] > 3 * threshold))
    m = min(n, good.size, bad.size)
    a, b = points[good[:m]], points[bad[:m]]
    na, nb = normals[good[:m]], normals[bad[:m]]
    target = threshold * spread ** rng.uniform(-1.0, 1.0, size=m)

    def at(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p = (1 - t)[:, None, None] * a + t[:, None, None] * b
        v = (1 - t)[:, None, None] * na + t[:, None, None] * nb
        return p, v / np.linalg.norm(v, axis=-1, keepdims=True)

    lo, hi = np.zeros(m), np.ones(m)
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        loss = _clarabel(*at(mid), convention, tight=True).losses
        above = ~(loss <= target)
        hi = np.where(above, mid, hi)
        lo = np.where(above, lo, mid)
    return at(hi)


def near_threshold_report(
    name: str, points: np.ndarray, normals: np.ndarray, convention: str, spread: float
) -> dict[str, object]:
    """Loss distribution of a near-threshold set and every method's verdicts against a tight
    reference on it (printed; returned for the JSON file)."""
    threshold = PAPER.threshold
    start = time.perf_counter()
    default = _clarabel(points, normals, convention, tight=False)
    default_seconds = time.perf_counter() - start
    start = time.perf_counter()
    tight = _clarabel(points, normals, convention, tight=True)
    tight_seconds = time.perf_counter() - start
    reference = best_of(default, tight)
    truth = reference.losses <= threshold
    unsettled = ~truth & ~(reference.lower > threshold)
    ratio = reference.losses / threshold
    edges = spread ** np.linspace(-1.0, 1.0, 7)
    counts, _ = np.histogram(ratio, bins=np.concatenate([[0.0], edges, [np.inf]]))
    n = len(points)
    print(
        f"{name}: {n} pairs, targets log-uniform in [threshold / {spread:g}, "
        f"{spread:g} threshold]; reference loss / threshold, quantiles 0/5/25/50/75/95/100%:"
    )
    print(
        "  " + " ".join(f"{q:.3f}" for q in np.quantile(ratio, [0, 0.05, 0.25, 0.5, 0.75, 0.95, 1]))
    )
    inner = [f"{lo:.3f}-{hi:.3f}" for lo, hi in itertools.pairwise(edges)]
    labels = [f"<{edges[0]:.3f}", *inner, f">{edges[-1]:.3f}"]
    print(
        "  histogram (log-uniform gives equal middle bins): "
        + ", ".join(f"{label} {count}" for label, count in zip(labels, counts, strict=True))
    )
    rows: list[dict[str, object]] = [
        {
            "method": "clarabel, default tolerances",
            "seconds": default_seconds,
            "disagree": int(((default.losses <= threshold) != truth).sum()),
            "tight_resolves": 0,
        },
        {
            "method": "clarabel, tight tolerances",
            "seconds": tight_seconds,
            "disagree": int(((tight.losses <= threshold) != truth).sum()),
            "tight_resolves": len(points),
        },
    ]
    for label, kwargs in (
        ("evaluate clarabel", {"method": "clarabel"}),
        ("evaluate auto (exact loss)", {"method": "auto"}),
        ("evaluate auto (verdict only)", {"method": "auto", "loss_rtol": None}),
    ):
        start = time.perf_counter()
        result = evaluate(points, normals, convention=convention, **kwargs)
        seconds = time.perf_counter() - start
        rows.append(
            {
                "method": label,
                "seconds": seconds,
                "disagree": int((result.passed != truth).sum()),
                "tight_resolves": int((result.solved_by == SOLVED_CLARABEL_TIGHT).sum()),
                "changed_by_resolve": int((result.passed != (default.losses <= threshold)).sum()),
                "unproven": int((~result.verdict_proven).sum()),
            }
        )
    print(
        f"  {'method':30s} {'seconds':>8s} {'disagree':>9s} {'unproven':>9s} "
        f"{'tight re-solves':>16s} {'vs default':>11s}"
    )
    for row in rows:
        print(
            f"  {row['method']:30s} {row['seconds']:8.3f} {row['disagree']:9d} "
            f"{row.get('unproven', '-')!s:>9s} {row['tight_resolves']!s:>16s} "
            f"{row.get('changed_by_resolve', '-')!s:>11s}"
        )
    gap = (default.losses - default.lower) / threshold
    band = (default.losses > threshold) & ~(default.lower > threshold)
    print(
        f"  default solve: (attained - dual bound) / threshold median {np.median(gap):.2e}, "
        f"max {gap.max():.2e}; bounds straddle the threshold on {int(band.sum())} pairs"
        + (
            f", losses {default.losses[band].min() / threshold:.4f}-"
            f"{default.losses[band].max() / threshold:.4f} threshold"
            if band.any()
            else ""
        )
    )
    print(
        "  disagree: verdicts that differ from the reference; unproven: failures without a dual "
        "bound above the threshold; vs default: verdicts that differ from the default Clarabel "
        f"solve's. Reference: {int(truth.sum())} passes, {int(unsettled.sum())} failures it "
        "cannot prove either"
    )
    return {
        "name": name,
        "spread": spread,
        "pairs": n,
        "loss_over_threshold_quantiles": np.quantile(ratio, [0, 0.25, 0.5, 0.75, 1]).tolist(),
        "histogram": dict(zip(labels, counts.tolist(), strict=True)),
        "reference_unsettled": int(unsettled.sum()),
        "default_gap_over_threshold_max": float(gap.max()),
        "default_straddling": int(band.sum()),
        "rows": rows,
    }


def cvxpy_loop(points: np.ndarray, axes: np.ndarray) -> tuple[np.ndarray, float]:
    """The released code's per-pair CVXPY problem (rank test, four SOC pairs, norm objective)."""
    import cvxpy as cp

    w = PAPER.gravity_wrench()
    G_all = grasp_matrix(points, axes)
    passed = np.zeros(len(points), dtype=bool)
    start = time.perf_counter()
    for i, G in enumerate(G_all):
        if np.linalg.matrix_rank(G) != 6:
            continue
        f = [cp.Variable(3) for _ in range(4)]
        constraints = [cp.norm(fk) <= PAPER.f_high for fk in f]
        constraints += [cp.SOC(PAPER.mu * fk[2], fk[0:2]) for fk in f]
        wrench = sum(G[:, 3 * k : 3 * k + 3] @ f[k] for k in range(4))
        problem = cp.Problem(cp.Minimize(cp.norm(wrench + w)), constraints)
        problem.solve()
        passed[i] = problem.value < PAPER.threshold
    return passed, time.perf_counter() - start


def timed(label: str, points: np.ndarray, normals: np.ndarray, **kwargs: object):
    evaluate(points[:64], normals[:64], **kwargs)  # compile / warm up outside the timing
    start = time.perf_counter()
    result = evaluate(points, normals, **kwargs)
    return label, result, time.perf_counter() - start


def main() -> None:
    args = parse()
    rng = np.random.default_rng(args.seed)
    parts: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    parts["near_threshold"] = near_threshold(args.near_threshold, rng, args.convention)
    at_threshold = near_threshold(args.near_threshold, rng, args.convention, spread=1.01)
    near = [
        near_threshold_report("near-threshold set", *parts["near_threshold"], args.convention, 3.0),
        near_threshold_report("within 1 % (stress)", *at_threshold, args.convention, 1.01),
    ]
    remaining = args.pairs - len(parts["near_threshold"][0])
    real = real_repaired(remaining // 2, rng)
    if real is not None:
        parts["real_repaired"] = real
        remaining -= len(real[0])
    per_family = -(-remaining // len(FAMILIES))
    for family in FAMILIES:
        parts[family] = family_pairs(family, per_family, rng)
    names = np.concatenate([[name] * len(p) for name, (p, _) in parts.items()])
    points = np.concatenate([p for p, _ in parts.values()])
    normals = np.concatenate([n for _, n in parts.values()])
    order = rng.permutation(len(points))  # mixed difficulty in every chunk
    points, normals, names = points[order], normals[order], names[order]
    n = len(points)
    print(
        f"{n} pairs, convention {args.convention}: "
        + ", ".join(f"{name} {int((names == name).sum())}" for name in parts)
    )

    axes = _axes(normals, args.convention)
    sub = rng.choice(n, size=min(args.cvxpy_pairs, n), replace=False)
    cvx_passed, cvx_seconds = cvxpy_loop(points[sub], axes[sub])
    cvx_rate = len(sub) / cvx_seconds

    runs = [
        timed("clarabel", points, normals, method="clarabel", convention=args.convention),
        timed("fast (exact loss)", points, normals, method="fast", convention=args.convention),
        timed("auto (exact loss)", points, normals, method="auto", convention=args.convention),
        timed(
            "auto (verdict only)",
            points,
            normals,
            method="auto",
            convention=args.convention,
            loss_rtol=None,
        ),
    ]
    reference, reference_seconds = runs[0][1], runs[0][2]
    cvx_agree = int((cvx_passed == reference.passed[sub]).sum())
    rows = [
        {
            "method": "cvxpy loop (release-style)",
            "pairs": len(sub),
            "seconds": cvx_seconds,
            "pairs_per_s": cvx_rate,
            "ratio_to_cvxpy": 1.0,
            "ratio_to_clarabel": (len(sub) / cvx_seconds) / (n / reference_seconds),
            "fallback": None,
            "verdict_disagreements": int(len(sub) - cvx_agree),
        }
    ]
    for label, result, seconds in runs:
        failing = reference.rank_ok & ~reference.passed
        exact = result.loss_converged[:, 0] & failing
        rel = np.abs(result.loss[exact] - reference.loss[exact]) / reference.loss[exact]
        rows.append(
            {
                "method": label,
                "pairs": n,
                "seconds": seconds,
                "pairs_per_s": n / seconds,
                "ratio_to_cvxpy": (n / seconds) / cvx_rate,
                "ratio_to_clarabel": reference_seconds / seconds,
                "fallback": result.fallback_fraction if label != "clarabel" else None,
                "verdict_disagreements": int((result.passed != reference.passed).sum()),
                "max_rel_loss_error_failing": float(rel.max()) if rel.size else 0.0,
            }
        )
    print(
        f"{'method':28s} {'pairs':>7s} {'pairs/s':>10s} {'x cvxpy':>9s} {'x clarabel':>10s} "
        f"{'fallback':>9s} {'disagree':>9s} {'loss err':>9s}"
    )
    for row in rows:
        fallback = "-" if row["fallback"] is None else f"{100 * row['fallback']:.3f}%"
        error = row.get("max_rel_loss_error_failing")
        loss_error = "-" if error is None or row["method"] == "clarabel" else f"{error:.1e}"
        print(
            f"{row['method']:28s} {row['pairs']:7d} {row['pairs_per_s']:10.0f} "
            f"{row['ratio_to_cvxpy']:9.0f} {row['ratio_to_clarabel']:10.2f} {fallback:>9s} "
            f"{row['verdict_disagreements']:9d} {loss_error:>9s}"
        )
    print(
        "disagree: verdicts that differ from Clarabel's (the cvxpy row: on its subsample); "
        "loss err: largest relative difference from Clarabel's loss over failing pairs whose "
        "loss is converged (verdict-only mode converges none: its losses are upper bounds)"
    )
    print(
        f"passing share (clarabel): {reference.passed.mean():.3f}; rank-deficient: "
        f"{(~reference.rank_ok).mean():.4f}"
    )
    for name in parts:
        mask = names == name
        print(f"  {name:15s} pass {reference.passed[mask].mean():.3f}")
    if args.json:
        from dg16m_core.atomic import write_json_atomic

        write_json_atomic(
            Path(args.json), {"convention": args.convention, "rows": rows, "near_threshold": near}
        )


if __name__ == "__main__":
    main()
