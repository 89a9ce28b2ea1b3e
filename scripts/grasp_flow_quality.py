"""Sample quality of the learned dual-grasp generator beside the dataset's own rates (issue 59).

For objects of a dataset's validation split (never trained on), the generator pipeline of
:class:`baselines.flow_predictor.FlowPredictor` runs on the cloud the cloud track's cameras see of
each object (kinect noise), and every dual candidate it pairs (before ranking) is labelled on the
full mesh by the benchmark's force-closure check (:func:`dg16m_env.evaluators.fce.fce_verdicts`).
Printed and written as JSON, per source (the generator's candidates; the dataset's own dual grasps
of the same objects):

* force-closure pass rate: candidates whose hands close on the full mesh and pass force closure
  (for the dataset: 200 of each object's stored dual grasps, re-checked the same way; the dataset
  keeps passing and failing pairs about half and half);
* collision rate: candidates with an open hand inside the full mesh;
* coverage: the share of the object's passing dataset dual grasps that have a generated
  candidate within 3 cm and 15 degrees (both hands, in either order; a hand turned half a turn
  about its approach is the same hand). The command::

    .venv/bin/python scripts/grasp_flow_quality.py --dataset runs/dataset --objects 50 \\
        --out runs/grasp_flow/quality.json
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from baselines.cloud_predictor import PAPER_FORCE_CLOSURE
from baselines.flow_predictor import FlowPredictor
from dataset_gen.grasps.gripper import get_gripper
from dataset_gen.objects.grasp_object import load_object
from dg16m_core.atomic import write_json_atomic
from dg16m_core.progress import progress_bar
from dg16m_env.evaluators.fce import REASONS, fce_verdicts
from dg16m_env.subjects.cloud_observation import cloud_observation
from dg16m_env.training.grasp_dataset import dataset_objects, read_object_grasps

COVER_DISTANCE = 0.03
"""m between grasp centres for a dataset hand to count as covered."""

COVER_ANGLE = np.radians(15.0)
"""Largest rotation between hands for a dataset hand to count as covered (rad)."""

CONTACT_DEPTH = get_gripper("panda").contact_depth
"""The Panda's grasp centre along its approach (m)."""


def hand_match(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(A, B) bool: hand ``a[i]`` (A, 4, 4) lies within :data:`COVER_DISTANCE` and
    :data:`COVER_ANGLE` of hand ``b[j]`` (B, 4, 4) (grasp centres; rotation up to the half turn
    about the approach axis)."""
    ca = a[:, :3, 3] + CONTACT_DEPTH * a[:, :3, 1]
    cb = b[:, :3, 3] + CONTACT_DEPTH * b[:, :3, 1]
    near = np.linalg.norm(ca[:, None] - cb[None], axis=-1) <= COVER_DISTANCE
    flip = np.diag([-1.0, 1.0, -1.0])  # half a turn about y
    best = np.zeros(near.shape)
    for turn in (np.eye(3), flip):
        relative = np.einsum("aji,bjk->abik", a[:, :3, :3], b[:, :3, :3] @ turn)
        cosine = (np.trace(relative, axis1=-2, axis2=-1) - 1.0) / 2.0
        best = np.maximum(best, cosine)
    return near & (best >= np.cos(COVER_ANGLE))


def coverage(dataset_pairs: np.ndarray, generated: np.ndarray) -> float:
    """Share of ``dataset_pairs`` (N, 2, 4, 4) with a pair of ``generated`` (M, 2, 4, 4) that
    matches both hands in one order or the other (:func:`hand_match`)."""
    if len(dataset_pairs) == 0:
        return float("nan")
    if len(generated) == 0:
        return 0.0
    m = [[hand_match(dataset_pairs[:, i], generated[:, j]) for j in (0, 1)] for i in (0, 1)]
    covered = ((m[0][0] & m[1][1]) | (m[0][1] & m[1][0])).any(axis=1)
    return float(covered.mean())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--dataset", type=Path, required=True)
    parser.add_argument("--objects", type=int, default=50)
    parser.add_argument("--generator", default=None, help="generator checkpoint (default shipped)")
    parser.add_argument(
        "--proposals",
        default="generator",
        help="the hands paired: generator (default), generator+sampler or sampler",
    )
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()

    records = dataset_objects(args.dataset, ("validation",))
    rng = np.random.default_rng(0)
    chosen = [records[i] for i in np.sort(rng.permutation(len(records))[: args.objects])]
    predictor = FlowPredictor(generator_checkpoint=args.generator, proposals=args.proposals)
    generated = {"candidates": 0, "pass": 0, "collision": 0, "coverage": []}
    own = {"candidates": 0, "pass": 0, "collision": 0}
    started = time.monotonic()
    for record in progress_bar(chosen, desc="objects", unit="object"):
        obj = load_object(record.mesh, object_id=record.object_id, scale=1.0, allow_any_size=True)
        _, candidates, _, _ = predictor.candidates(cloud_observation(obj))
        stored = read_object_grasps(record.grasps)
        if candidates.n:
            codes, _ = fce_verdicts(obj, candidates.poses, PAPER_FORCE_CLOSURE)
            generated["pass"] += int((codes == REASONS.index("pass")).sum())
            generated["collision"] += int((codes == REASONS.index("collision")).sum())
        generated["candidates"] += candidates.n
        generated["coverage"].append(coverage(stored.poses[stored.force_closure], candidates.poses))
        rows = rng.choice(len(stored.poses), min(200, len(stored.poses)), replace=False)
        codes, _ = fce_verdicts(obj, stored.poses[rows].astype(np.float64), PAPER_FORCE_CLOSURE)
        own["candidates"] += len(rows)
        own["pass"] += int((codes == REASONS.index("pass")).sum())
        own["collision"] += int((codes == REASONS.index("collision")).sum())
    table = {
        "objects": len(chosen),
        "proposals": args.proposals,
        "seconds": round(time.monotonic() - started, 1),
        "generator": {
            "candidates": generated["candidates"],
            "force_closure_rate": generated["pass"] / max(generated["candidates"], 1),
            "collision_rate": generated["collision"] / max(generated["candidates"], 1),
            "coverage": float(np.nanmean(generated["coverage"])),
        },
        "dataset": {
            "candidates": own["candidates"],
            "force_closure_rate": own["pass"] / max(own["candidates"], 1),
            "collision_rate": own["collision"] / max(own["candidates"], 1),
            "coverage": 1.0,  # by definition
        },
    }
    print(table)
    if args.out is not None:
        write_json_atomic(args.out, table)


if __name__ == "__main__":
    main()
