"""Force-closure throughput: our methods against a CVXPY per-pair loop, in the same run.

Builds at least 50,000 four-contact pairs of mixed difficulty:

* real: single-arm contact pairs of the DG16M release's airplane file, re-paired at random into
  new dual grasps (normals = face normals of the faces the contacts lie on), when
  ``../shared/data/real`` is present;
* synthetic families from :mod:`dataset_gen.force_closure.synthetic` (antipodal on spheres,
  pinches on boxes, random, near-collinear);
* near-threshold: pairs moved along a path from a passing to a failing configuration until
  Clarabel's loss lies within a factor 3 of the threshold (the hardest verdicts).

Then times, on one core: a CVXPY loop written like the released code (subsample), Clarabel on
every pair (the reference verdicts), and ``fast`` / ``auto`` in exact-loss and verdict-only modes.
Prints pairs/s, the ratio to the CVXPY loop, the share sent to Clarabel, and verdict agreement
with Clarabel on every pair.

    .venv/bin/python bench/fc_throughput.py            # about two minutes
    .venv/bin/python bench/fc_throughput.py --json runs/fc_throughput.json
"""

from __future__ import annotations

import os

# One core: no BLAS or numba threads (set before numpy is imported).
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dataset_gen.force_closure import evaluate, grasp_matrix
from dataset_gen.force_closure.synthetic import FAMILIES, family_pairs

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


def near_threshold(
    n: int, rng: np.random.Generator, convention: str
) -> tuple[np.ndarray, np.ndarray]:
    """Bisect along straight paths from passing to failing box pinches to L ~ threshold."""
    points, normals = family_pairs("box", 20 * n, rng)
    result = evaluate(points, normals, convention=convention, loss_rtol=None)
    good = np.flatnonzero(result.passed)
    bad = np.flatnonzero(result.rank_ok & ~result.passed)
    m = min(n, good.size, bad.size)
    a, b = points[good[:m]], points[bad[:m]]
    na, nb = normals[good[:m]], normals[bad[:m]]

    def at(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p = (1 - t)[:, None, None] * a + t[:, None, None] * b
        v = (1 - t)[:, None, None] * na + t[:, None, None] * nb
        return p, v / np.linalg.norm(v, axis=-1, keepdims=True)

    lo, hi = np.zeros(m), np.ones(m)
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        p, v = at(mid)
        loss = evaluate(p, v, convention=convention, method="clarabel").loss
        above = ~(loss <= 1e-5)
        hi = np.where(above, mid, hi)
        lo = np.where(above, lo, mid)
    # Spread the final loss over [threshold / 3, 3 * threshold] on both sides of it.
    t = lo + (hi - lo) * rng.uniform(-2.0, 3.0, size=m)
    return at(np.clip(t, 0.0, 1.0))


def cvxpy_loop(points: np.ndarray, axes: np.ndarray) -> tuple[np.ndarray, float]:
    """The released code's per-pair CVXPY problem (rank test, four SOC pairs, norm objective)."""
    import cvxpy as cp

    w = np.array([0.0, 0.0, -60.0, 0.0, 0.0, 0.0])
    G_all = grasp_matrix(points, axes)
    passed = np.zeros(len(points), dtype=bool)
    start = time.perf_counter()
    for i, G in enumerate(G_all):
        if np.linalg.matrix_rank(G) != 6:
            continue
        f = [cp.Variable(3) for _ in range(4)]
        constraints = [cp.norm(fk) <= 70.0 for fk in f]
        constraints += [cp.SOC(0.4 * fk[2], fk[0:2]) for fk in f]
        wrench = sum(G[:, 3 * k : 3 * k + 3] @ f[k] for k in range(4))
        problem = cp.Problem(cp.Minimize(cp.norm(wrench + w)), constraints)
        problem.solve()
        passed[i] = problem.value < 1e-5
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

    axes = -normals if args.convention == "physical" else normals
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
    reference = runs[0][1]
    cvx_agree = int((cvx_passed == reference.passed[sub]).sum())
    rows = [
        {
            "method": "cvxpy loop (release-style)",
            "pairs": len(sub),
            "seconds": cvx_seconds,
            "pairs_per_s": cvx_rate,
            "ratio_to_cvxpy": 1.0,
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
                "fallback": result.fallback_fraction if label != "clarabel" else None,
                "verdict_disagreements": int((result.passed != reference.passed).sum()),
                "max_rel_loss_error_failing": float(rel.max()) if rel.size else 0.0,
            }
        )
    print(
        f"{'method':28s} {'pairs':>7s} {'pairs/s':>10s} {'x cvxpy':>9s} {'fallback':>9s} "
        f"{'disagree':>9s} {'loss err':>9s}"
    )
    for row in rows:
        fallback = "-" if row["fallback"] is None else f"{100 * row['fallback']:.3f}%"
        error = row.get("max_rel_loss_error_failing")
        loss_error = "-" if error is None or row["method"] == "clarabel" else f"{error:.1e}"
        print(
            f"{row['method']:28s} {row['pairs']:7d} {row['pairs_per_s']:10.0f} "
            f"{row['ratio_to_cvxpy']:9.0f} {fallback:>9s} {row['verdict_disagreements']:9d} "
            f"{loss_error:>9s}"
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
        from dataset_gen.atomic import write_json_atomic

        write_json_atomic(Path(args.json), {"convention": args.convention, "rows": rows})


if __name__ == "__main__":
    main()
