"""Train a dual-grasp classifier (CGDF or Dual-PointNetGPD) on generated DG16M-style data, with
our force-closure labels or DA2-style labels, then score it on the benchmark.

Reads top to bottom (CleanRL style): one dataclass of arguments, then the run.

1. Load the objects of a ``dg16m generate`` folder of procedural TRAIN objects (disjoint from the
   benchmark's by construction: ``--split train``), each with its point cloud, its dual grasps
   and two labels per grasp (:mod:`baselines.classifier_data`); hold out ``val_fraction`` of the
   objects.
2. Train with Adam on balanced batches (B objects x n grasps, half positives and half negatives
   per object) and binary cross-entropy, until ``steps`` or ``time_budget_s``; every
   ``eval_every`` steps measure the loss and ROC AUC on the held-out objects.
3. Write the checkpoint (``<model>-<labels>.pt``), the learning curve (PNG) and the history.
4. Score the trained model with the registered ``classifier`` evaluator on the benchmark (the
   paper's Table II protocol: FCE and GSR of the top-k candidates per object) and write the
   results.

    .venv/bin/dg16m generate --procedural 200 --split train --out runs/train200 --workers 2
    .venv/bin/python -m baselines.train_classifier --model cgdf --labels dg16m \\
        --data runs/train200 --out runs/classifiers
    .venv/bin/python -m baselines.train_classifier --model pointnetgpd --labels da2 ...

Budget: the defaults train for at most 15 minutes on one core (6,000 steps of 8 objects x 32
grasps, or the time budget), then score the benchmark in about a minute; two runs side by side
fill two cores (see baselines/RESULTS.md).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from baselines.classifier_data import (
    LABELS,
    BatchSampler,
    ClassifierDataError,
    load_generated,
    split_objects,
)
from baselines.da2_labels import roc_auc
from baselines.sb3_common import parse_args, write_run
from dg16m_core.atomic import atomic_path, write_json_atomic

MODELS = ("cgdf", "pointnetgpd")


@dataclass
class Args:
    model: str = "cgdf"
    """cgdf (neural descriptor field, rotation-equivariant) or pointnetgpd (Dual-PointNetGPD)"""
    labels: str = "dg16m"
    """dg16m (our force-closure verdicts) or da2 (DA2's frictionless criterion, same grasps)"""
    data: Path = Path("runs/train200")
    """a 'dg16m generate --split train' folder"""
    more_data: str = ""
    """further 'dg16m generate' folders, comma-separated, whose objects join those of --data
    (the real training split beside the procedural one); --limit applies to each"""
    mesh_root: str = ""
    """the --meshes folder of 'dg16m generate --meshes' datasets (procedural ones carry theirs)"""
    out: Path = Path("runs/classifiers")
    """output folder: checkpoint, learning curve, history, results"""
    limit: int = 0
    """use the first N objects only (0: all)"""
    val_fraction: float = 0.1
    """fraction of the objects held out for validation"""
    objects_per_batch: int = 8
    """objects per training batch"""
    grasps_per_object: int = 32
    """grasps per object in a batch (half positives, half negatives)"""
    steps: int = 6000
    """Adam steps at most (or until time_budget_s)"""
    time_budget_s: float = 900.0
    """stop training after this many seconds even if steps remain"""
    learning_rate: float = 1e-3
    """Adam learning rate"""
    eval_every: int = 250
    """steps between validation loss and ROC AUC measurements"""
    val_grasps: int = 256
    """grasps per held-out object in each validation (a fixed seeded subset)"""
    seed: int = 0
    """seed of the split, the batches and the initial weights"""
    threads: int = 1
    """torch threads (the shipped checkpoints were trained with 1, two runs side by side)"""
    k: int = 10
    """top-k of the benchmark evaluation"""
    benchmark: str = "procedural"
    """the benchmark of the evaluation: a file, or a shipped one by name (procedural, real)"""
    evaluate: bool = True
    """score on the benchmark with the classifier evaluator at the end"""


def build_model(name: str, seed: int) -> Any:
    """A fresh model with its default configuration and the given initialisation seed."""
    if name == "cgdf":
        from baselines.cgdf_classifier import CGDFClassifier, CGDFConfig

        return CGDFClassifier(CGDFConfig(seed=seed))
    if name == "pointnetgpd":
        from baselines.dual_pointnet_gpd import DualPointNetGPD, DualPointNetGPDConfig

        return DualPointNetGPD(DualPointNetGPDConfig(seed=seed))
    raise ClassifierDataError(f"--model: expected one of {MODELS}, found {name!r}")


def validation_set(objects: list[Any], label: str, per_object: int, seed: int) -> list[tuple]:
    """A fixed seeded subset of each held-out object's grasps: ``(points, poses, labels)``."""
    rng = np.random.default_rng(seed)
    out = []
    for obj in objects:
        rows = rng.choice(len(obj.poses), min(per_object, len(obj.poses)), replace=False)
        out.append((obj.points, obj.poses[rows], obj.labels[label][rows]))
    return out


def validate(
    model: Any, val_set: list[tuple], step: int, started: float, running: list[float]
) -> dict[str, Any]:
    """The history entry at ``step``: mean training loss since the last entry, validation loss
    and ROC AUC on the held-out objects (printed)."""
    import torch

    loss_fn = torch.nn.BCEWithLogitsLoss()
    model.eval()
    scores, truth, losses = [], [], []
    with torch.no_grad():
        for points, poses, labels in val_set:
            out = model(torch.from_numpy(points), torch.from_numpy(poses))
            losses.append(float(loss_fn(out, torch.from_numpy(labels.astype(np.float32)))))
            scores.append(out.numpy())
            truth.append(labels)
    entry = {
        "step": step,
        "seconds": time.perf_counter() - started,
        "train_loss": float(np.mean(running)) if running else None,
        "val_loss": float(np.mean(losses)) if losses else None,
        "val_auc": roc_auc(np.concatenate(scores), np.concatenate(truth)) if scores else None,
    }
    print(
        f"step {step:>5}  {entry['seconds']:6.0f} s  train {entry['train_loss'] or 0:.4f}  "
        f"val {entry['val_loss'] or float('nan'):.4f}  AUC {entry['val_auc'] or 0:.3f}",
        flush=True,
    )
    return entry


def plot_history(path: Path, history: list[dict[str, Any]], title: str) -> None:
    """Training loss, validation loss and validation AUC against steps."""
    fig = Figure(figsize=(6.4, 4.2))
    ax = fig.add_subplot()
    steps = [h["step"] for h in history]
    ax.plot(steps, [h["train_loss"] for h in history], label="train loss (BCE)")
    ax.plot(steps, [h["val_loss"] for h in history], label="validation loss")
    ax.set_xlabel("step")
    ax.set_ylabel("binary cross-entropy")
    right = ax.twinx()
    right.plot(steps, [h["val_auc"] for h in history], color="C3", label="validation ROC AUC")
    right.set_ylim(0.4, 1.0)
    right.set_ylabel("ROC AUC")
    lines = ax.get_legend_handles_labels()[0] + right.get_legend_handles_labels()[0]
    ax.legend(lines, [line.get_label() for line in lines], loc="center right", fontsize=8)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=120)


def main(args: Args | None = None) -> dict[str, Any]:
    args = args or parse_args(Args, __doc__.split("\n\n")[0])
    import torch

    from baselines.grasp_geometry import save_checkpoint
    from dg16m_env.evaluators import make

    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)  # dropout-free models; this only fixes torch's own kernels
    if args.labels not in LABELS:
        raise ClassifierDataError(f"--labels: expected one of {LABELS}, found {args.labels!r}")
    args.out.mkdir(parents=True, exist_ok=True)
    name = f"{args.model}-{args.labels}"

    # 1. data
    folders = [args.data, *(Path(f) for f in args.more_data.split(",") if f.strip())]
    objects = [
        o
        for f in folders
        for o in load_generated(
            f, limit=args.limit or None, seed=args.seed, mesh_root=args.mesh_root or None
        )
    ]
    ids = [o.object_id for o in objects]
    if len(set(ids)) != len(ids):
        repeated = sorted({i for i in ids if ids.count(i) > 1})
        raise ClassifierDataError(
            f"--data and --more-data: expected distinct objects, found {repeated[:3]} twice"
        )
    train, val = split_objects(objects, args.val_fraction, args.seed)
    positives = sum(int(o.labels[args.labels].sum()) for o in train)
    total = sum(len(o.poses) for o in train)
    print(f"{len(train)} training objects ({positives}/{total} positive), {len(val)} held out")
    sampler = BatchSampler(
        train,
        args.labels,
        args.objects_per_batch,
        args.grasps_per_object,
        np.random.default_rng(args.seed),
    )
    val_set = validation_set(val, args.labels, args.val_grasps, args.seed + 1)

    # 2. training
    model = build_model(args.model, args.seed)
    optimizer = torch.optim.Adam(model.parameters(), lr=args.learning_rate)
    loss_fn = torch.nn.BCEWithLogitsLoss()
    history: list[dict[str, Any]] = []
    running: list[float] = []
    started = time.perf_counter()
    step = 0
    while step < args.steps and time.perf_counter() - started < args.time_budget_s:
        points, poses, labels = sampler.sample()
        model.train()
        logits = model.forward_batch(torch.from_numpy(points), torch.from_numpy(poses))
        loss = loss_fn(logits, torch.from_numpy(labels))
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        running.append(float(loss.detach()))
        step += 1
        if step % args.eval_every == 0:
            history.append(validate(model, val_set, step, started, running))
            running = []
    if step and (not history or history[-1]["step"] != step):
        history.append(validate(model, val_set, step, started, running))
    train_s = time.perf_counter() - started

    # 3. checkpoint, curve, history
    checkpoint = args.out / f"{name}.pt"
    save_checkpoint(
        checkpoint,
        model,
        {
            "labels": args.labels,
            "steps": step,
            "train_seconds": train_s,
            "data": ",".join(str(f) for f in folders),
        },
    )
    plot_history(args.out / f"{name}-curve.png", history, f"{name}: {step} steps, {train_s:.0f} s")
    write_json_atomic(args.out / f"{name}-history.json", history)

    # 4. the benchmark
    results = {}
    if args.evaluate:
        model.eval()
        results["classifier"] = make(
            "classifier", k=args.k, benchmark=args.benchmark, progress=True
        ).evaluate(model)
        print(results["classifier"].format())
    write_run(
        args.out / f"{name}-results.json",
        args,
        results,
        steps=step,
        train_seconds=train_s,
        train_objects=len(train),
        held_out_objects=len(val),
        final=history[-1] if history else None,
    )
    print(f"wrote {checkpoint} and {name}-curve.png, -history.json, -results.json in {args.out}")
    return {"history": history, "steps": step}


if __name__ == "__main__":
    main()
