"""Train the learned dual-grasp generator and its ranker on a dataset folder (issue 59).

Reads top to bottom (CleanRL style): one dataclass of arguments, then three stages, each resumed
from the last checkpoint when the command is run again with the same arguments (so the training
can be split into runs of an hour or two; Ctrl-C saves and stops).

1. **generator**: :class:`baselines.dual_grasp_flow.AnchoredGraspFlow` learns, by flow
   matching, the hands of the force-closure dual grasps of the ``train`` objects of a ``dg16m
   dataset build`` folder, each about its anchor (the cloud point nearest to its grasp centre),
   given the cloud the cloud track's cameras see of the object (the loader's
   ``cloud="partial"``, :mod:`dg16m_env.training.grasp_dataset`, ``n_points`` points), and
   which cloud points are graspable. Labels come from the full mesh, so the model learns where
   the unseen parts probably are. Batches: ``objects_per_batch`` objects x
   ``grasps_per_batch`` of their anchored hands (a seeded subset of ``grasps_per_object``),
   each cloud in a random order, the object and its hands turned about the vertical by a
   random angle (gravity stays -z). Adam with a cosine decay to a tenth. The validation
   objects' loss is measured every ``eval_every`` steps.
2. **samples**: the predictor's pipeline (:class:`baselines.flow_predictor.FlowPredictor` with
   the trained generator, its hands closed on ``check_points`` of the cloud, paired and checked)
   runs on the clouds of ``ranker_objects`` objects (a tenth of them validation objects);
   ``ranker_samples`` of each object's dual candidates (with ``ranker_pairs=
   "cloud_force_closure"``, of those passing force closure on the cloud) are labelled on the
   object's full mesh with the benchmark's force-closure check
   (:func:`dg16m_env.evaluators.fce.fce_verdicts`: the open hands must clear the whole mesh, the
   jaws close on it, the four contacts pass). One file per object (``samples/<id>.npz``),
   written atomically.
3. **ranker**: a :class:`baselines.dual_pointnet_gpd.DualPointNetGPD` learns those labels from
   the cloud (binary cross-entropy; batches of ``ranker_batch_objects`` objects x
   ``ranker_grasps`` samples, half passing where an object has both), validation ROC AUC on the
   held-out objects' samples every ``eval_every`` steps.

Writes to ``out``: ``state.pt`` (the resumable state), ``grasp-flow.pt`` and
``grasp-flow-ranker.pt`` (the checkpoints :mod:`baselines.flow_predictor` loads; copy them
to ``baselines/checkpoints/`` to ship them), ``history.json`` and ``curves.png``. The commands::

    .venv/bin/dg16m dataset build --out runs/dataset --workers 2
    .venv/bin/python -m baselines.train_dual_grasp_flow --dataset runs/dataset \\
        --out runs/grasp_flow

Randomness: every batch is drawn from generators seeded by ``(seed, stage, step)``, so a resumed
run computes the same steps as an uninterrupted one.
"""

from __future__ import annotations

import json
import math
import signal
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from baselines.sb3_common import parse_args
from dataset_gen.sources.object_source import object_seed
from dg16m_core.atomic import atomic_path, write_bytes_atomic, write_json_atomic
from dg16m_core.errors import Dg16mError
from dg16m_core.progress import progress_bar

STAGES = ("generator", "samples", "ranker", "done")
RANKER_PAIRS = ("all", "cloud_force_closure")
"""Values of ``--ranker-pairs``."""


class TrainingArgumentsError(Dg16mError, ValueError):
    """Arguments that cannot train, or a state file written with other arguments."""


@dataclass
class Args:
    dataset: Path = Path("runs/dataset")
    """a 'dg16m dataset build' folder"""
    out: Path = Path("runs/dual_grasp_flow")
    """output folder: state, checkpoints, history, curves, samples"""
    cache_dir: str = ""
    """folder of the objects' clouds across runs (default: OUT/clouds)"""
    limit: int = 0
    """use the first N train objects (and N validation objects) only (0: all)"""
    sources: str = ""
    """comma-separated collections to train both models on (the data card's source column, e.g.
    'sweethome3d', to fine-tune the shipped generator on furniture with --init-generator);
    empty: every collection"""
    init_generator: str = ""
    """start the generator from this checkpoint's weights (e.g. the shipped
    baselines/checkpoints/grasp-flow.pt, to fine-tune on another dataset); empty: from scratch"""
    n_points: int = 1024
    """points per cloud (the predictor's n_points)"""
    grasps_per_object: int = 128
    """anchored hands of passing dual grasps kept in memory per object (a seeded subset)"""
    objects_per_batch: int = 16
    """objects per generator batch"""
    grasps_per_batch: int = 32
    """hands per object in a generator batch"""
    generator_steps: int = 12000
    """generator Adam steps"""
    learning_rate: float = 1e-3
    """Adam's initial learning rate (cosine decay to a tenth)"""
    ranker_objects: int = 600
    """objects whose generated samples train the ranker (a tenth of them validation objects)"""
    ranker_samples: int = 64
    """generated dual grasps per object for the ranker"""
    ranker_pairs: str = "all"
    """which of an object's dual candidates its ranker samples are drawn from: 'all' (the shipped
    ranker's) or 'cloud_force_closure' (only those whose cloud contacts pass force closure: the
    group the predictor ranks first, whose order decides most objects' top 10)"""
    check_points: int = 1024
    """cloud points the samples' hands are closed on and checked against (FlowPredictor's
    check_points; the shipped ranker's samples were made with 1024, the predictor checks 4096)"""
    ranker_steps: int = 3000
    """ranker Adam steps"""
    ranker_batch_objects: int = 8
    """objects per ranker batch"""
    ranker_grasps: int = 32
    """samples per object in a ranker batch"""
    eval_every: int = 500
    """steps between validation measurements"""
    checkpoint_every_s: float = 300.0
    """seconds between saves of the resumable state"""
    seed: int = 0
    """seed of the weights, the batches and the samples"""
    threads: int = 1
    """torch threads"""


# --------------------------------------------------------------------------------------------
# State: what a rerun resumes from
# --------------------------------------------------------------------------------------------


def _identity(args: Args) -> dict[str, Any]:
    """The arguments a resumed run must share with the run that wrote the state."""
    out = {k: str(v) if isinstance(v, Path) else v for k, v in asdict(args).items()}
    for free in ("out", "cache_dir", "checkpoint_every_s", "threads", "dataset"):
        out.pop(free)
    return out


def load_state(args: Args) -> dict[str, Any] | None:
    """The state of an earlier run in ``args.out`` (None: none).

    Raises:
        TrainingArgumentsError: a state written with other arguments.
    """
    import torch

    path = args.out / "state.pt"
    if not path.is_file():
        return None
    state = torch.load(path, map_location="cpu", weights_only=True)
    if state.get("identity") != _identity(args):
        theirs, ours = state.get("identity", {}), _identity(args)
        differ = sorted(k for k in set(theirs) | set(ours) if theirs.get(k) != ours.get(k))
        raise TrainingArgumentsError(
            f"{path}: expected a state of the same arguments, found one that differs in {differ}"
            " (use another --out, or delete the state to start over)"
        )
    return state


def save_state(args: Args, state: dict[str, Any]) -> None:
    """Write the state atomically."""
    import torch

    state["identity"] = _identity(args)
    with atomic_path(args.out / "state.pt") as tmp:
        torch.save(state, tmp)


class _StopRequestedError(Exception):
    """SIGTERM arrived: save the state and stop."""


def _on_signal(signum: int, frame: Any) -> None:
    raise _StopRequestedError(signal.Signals(signum).name)


# --------------------------------------------------------------------------------------------
# Data
# --------------------------------------------------------------------------------------------


def open_dataset(args: Args, split: str) -> Any:
    """The dataset's objects of one split with their partial clouds (cached)."""
    from dg16m_env.training.grasp_dataset import DualGraspDataset

    cache = args.cache_dir or str(args.out / "clouds")
    ds = DualGraspDataset(
        args.dataset,
        splits=(split,),
        cloud="partial",
        n_points=args.n_points,
        seed=0,
        cloud_cache=100_000,
        grasp_cache=1,
        cache_dir=cache,
    )
    if args.sources:
        wanted = set(args.sources.split(","))
        found = sorted({r.source for r in ds.records})
        ds.records = [r for r in ds.records if r.source in wanted]
        if not ds.records:
            raise TrainingArgumentsError(
                f"sources: expected some of {found} (the {split!r} split's), found {args.sources!r}"
            )
        ds.object_ids = [r.object_id for r in ds.records]
    if args.limit:
        ds.records = ds.records[: args.limit]
        ds.object_ids = ds.object_ids[: args.limit]
    return ds


def passing_hands(
    ds: Any, per_object: int, seed: int, config: Any, contact_depth: float
) -> tuple[np.ndarray, ...]:
    """The hands of each object's passing dual grasps with their anchors on its cloud.

    A hand's anchor is the cloud point nearest to its grasp centre; a hand farther than
    ``config.anchor_radius`` (m) from every point (on a part the cameras did not see) is left
    out. A cloud point is graspable when a grasp centre lies within ``config.graspable_radius``.

    Returns:
        ``indices (O,)`` of the objects with an anchored hand, ``hands (O, per_object, 4, 4)``
        float32 (a seeded subset of the distinct ones, repeated when fewer), ``anchors (O,
        per_object)`` int64 indices into each object's cloud and ``graspable (O, P)`` bool.
    """
    from scipy.spatial import cKDTree

    keep, hands, anchors, graspable = [], [], [], []
    for index in progress_bar(range(len(ds.records)), desc="grasps", unit="object"):
        grasps = ds.object_grasps(index)
        passing = grasps.poses[grasps.force_closure].reshape(-1, 4, 4)
        if len(passing) == 0:
            continue
        distinct = np.unique(passing.reshape(len(passing), 16), axis=0).reshape(-1, 4, 4)
        centres = distinct[:, :3, 3] + contact_depth * distinct[:, :3, 1]
        cloud = ds.object_cloud(index)
        distance, nearest = cKDTree(cloud).query(centres)
        anchored = distance <= config.anchor_radius
        if not anchored.any():
            continue
        rng = np.random.default_rng(object_seed(seed, f"hands:{ds.object_ids[index]}"))
        rows = np.flatnonzero(anchored)
        take = np.sort(rng.choice(rows, per_object, replace=rows.size < per_object))
        keep.append(index)
        hands.append(distinct[take])
        anchors.append(nearest[take])
        graspable.append(cKDTree(centres).query(cloud)[0] <= config.graspable_radius)
    if not keep:
        n = ds._clouds.n_points
        return (
            np.zeros(0, np.int64),
            np.zeros((0, per_object, 4, 4), np.float32),
            np.zeros((0, per_object), np.int64),
            np.zeros((0, n), bool),
        )
    return (
        np.asarray(keep, dtype=np.int64),
        np.stack(hands).astype(np.float32),
        np.stack(anchors).astype(np.int64),
        np.stack(graspable),
    )


def turn_about_z(points: np.ndarray, poses: np.ndarray, angle: float) -> tuple[np.ndarray, ...]:
    """``points`` (P, 3) and ``poses`` (..., 4, 4) turned by ``angle`` (rad) about the object's
    vertical axis through its origin (the centre of mass)."""
    c, s = np.cos(angle), np.sin(angle)
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]], dtype=points.dtype)
    turned = poses.copy()
    turned[..., :3, :] = np.einsum("ij,...jk->...ik", turn, poses[..., :3, :])
    return points @ turn.T, turned


def generator_batch(
    args: Args, ds: Any, data: tuple[np.ndarray, ...], step: int, split: str
) -> tuple[np.ndarray, ...]:
    """``(clouds (B, P, 3), hands (B, G, 4, 4), anchors (B, G), candidates (B, G), graspable
    (B, G))`` of generator step ``step``: each cloud's points in a random order (its first
    points make the cloud's code), the object turned about the vertical by a random angle; the
    anchor head's candidates half graspable points (where an object has them), half any."""
    indices, hands, anchors, graspable = data
    rng = np.random.default_rng(object_seed(args.seed, f"generator-batch:{split}:{step}"))
    b, g = args.objects_per_batch, args.grasps_per_batch
    chosen = rng.choice(len(indices), b, replace=len(indices) < b)
    out: list[list[np.ndarray]] = [[], [], [], [], []]
    for row in chosen:
        cloud = ds.object_cloud(int(indices[row]))
        order = rng.permutation(len(cloud))
        where = np.empty_like(order)
        where[order] = np.arange(len(order))
        pick = rng.choice(hands.shape[1], g, replace=False)
        points, turned = turn_about_z(cloud[order], hands[row, pick], rng.uniform(0.0, 2.0 * np.pi))
        positive = np.flatnonzero(graspable[row])
        candidates = rng.choice(len(cloud), g)
        if positive.size:
            candidates[: g // 2] = rng.choice(positive, g // 2)
        for k, value in enumerate(
            (
                points,
                turned,
                where[anchors[row, pick]],
                where[candidates],
                graspable[row, candidates],
            )
        ):
            out[k].append(value)
    clouds, picked, anchor_rows, candidate_rows, labels = map(np.stack, out)
    return (
        clouds.astype(np.float32),
        picked.astype(np.float32),
        anchor_rows.astype(np.int64),
        candidate_rows.astype(np.int64),
        labels,
    )


# --------------------------------------------------------------------------------------------
# The training loop both models share
# --------------------------------------------------------------------------------------------


def run_steps(
    args: Args,
    stage: str,
    total: int,
    step: int,
    loss_of: Callable[[int], Any],
    optimizer: Any,
    scheduler: Any,
    measure: tuple[str, Callable[[], float]],
    snapshot: Callable[[int], dict[str, Any]],
    history: list[dict[str, Any]],
) -> int:
    """Steps ``step`` to ``total`` of one stage: ``loss_of(step)`` is the step's loss (a
    tensor), which ``optimizer`` minimises (then ``scheduler`` steps, unless None); every ``eval_every`` steps (and at the end) ``history`` gets the running loss and the
    validation measure ``measure = (name, function)``; the state is saved every
    ``checkpoint_every_s`` and on Ctrl-C / SIGTERM (then re-raised). Returns ``total``."""
    name, function = measure
    bar = progress_bar(total=total, initial=step, desc=stage, unit="step")
    saved, running = time.monotonic(), float("nan")
    try:
        while step < total:
            tensor = loss_of(step)
            optimizer.zero_grad()
            tensor.backward()
            optimizer.step()
            if scheduler is not None:
                scheduler.step()
            loss = tensor.item()
            step += 1
            running = loss if np.isnan(running) else 0.98 * running + 0.02 * loss
            bar.update(1)
            if step % args.eval_every == 0 or step == total:
                history.append(
                    {"stage": stage, "step": step, "train_loss": running, name: function()}
                )
                bar.set_postfix(loss=f"{running:.3f}", **{name: f"{history[-1][name]:.3f}"})
            if time.monotonic() - saved > args.checkpoint_every_s:
                save_state(args, snapshot(step))
                saved = time.monotonic()
    except (_StopRequestedError, KeyboardInterrupt):
        save_state(args, snapshot(step))
        raise
    finally:
        bar.close()
    return step


# --------------------------------------------------------------------------------------------
# Stage 1: the generator
# --------------------------------------------------------------------------------------------


def _cosine(total: int) -> Any:
    """Learning-rate factor at a step: cosine from 1 to 0.1 over ``total`` steps."""
    return lambda step: 0.1 + 0.45 * (1.0 + math.cos(math.pi * min(step, total) / max(total, 1)))


def _noise(args: Args, name: str, step: int) -> Any:
    import torch

    return torch.Generator().manual_seed(object_seed(args.seed, f"{name}:{step}") % 2**63)


def _generator_loss(model: Any, batch: tuple[np.ndarray, ...], noise: Any) -> Any:
    """The model's loss on a :func:`generator_batch`."""
    import torch

    clouds, hands, anchors, candidates, graspable = map(torch.from_numpy, batch)
    return model.loss(clouds, hands, anchors, noise, candidates, graspable)


def train_generator(args: Args, state: dict[str, Any]) -> dict[str, Any]:
    """Stage 1 (module docstring); returns the state at its end (or raises on a signal, saved)."""
    import torch

    from baselines.dual_grasp_flow import AnchoredGraspFlow, AnchoredGraspFlowConfig
    from baselines.grasp_geometry import load_checkpoint, save_checkpoint

    model = AnchoredGraspFlow(AnchoredGraspFlowConfig(seed=args.seed))
    train, val = open_dataset(args, "train"), open_dataset(args, "validation")
    config, depth = model.config, model.contact_depth
    t_data = passing_hands(train, args.grasps_per_object, args.seed, config, depth)
    v_data = passing_hands(val, args.grasps_per_object, args.seed, config, depth)
    if len(t_data[0]) == 0:
        raise TrainingArgumentsError(
            f"{args.dataset}: expected train objects with passing dual grasps, found none"
        )
    optimizer = torch.optim.Adam(model.parameters(), lr=args.learning_rate)
    scheduler = torch.optim.lr_scheduler.LambdaLR(optimizer, _cosine(args.generator_steps))
    step = int(state.get("step", 0))
    if "generator" in state:
        model.load_state_dict(state["generator"])
        optimizer.load_state_dict(state["optimizer"])
        scheduler.load_state_dict(state["scheduler"])
    elif args.init_generator:
        start, _ = load_checkpoint(args.init_generator, expected=model.name)
        if start.config != model.config:
            raise TrainingArgumentsError(
                f"--init-generator {args.init_generator}: expected the configuration "
                f"{model.config}, found {start.config}"
            )
        model.load_state_dict(start.state_dict())
    history: list[dict[str, Any]] = state.setdefault("history", [])

    def validation_loss() -> float:
        if len(v_data[0]) == 0:
            return float("nan")
        with torch.no_grad():
            losses = [
                _generator_loss(
                    model,
                    generator_batch(args, val, v_data, k, "val"),
                    _noise(args, "generator-val-noise", k),
                ).item()
                for k in range(4)
            ]
        return float(np.mean(losses))

    def snapshot(step: int) -> dict[str, Any]:
        return {
            **state,
            "stage": "generator",
            "step": step,
            "generator": model.state_dict(),
            "optimizer": optimizer.state_dict(),
            "scheduler": scheduler.state_dict(),
        }

    def loss_of(step: int) -> Any:
        batch = generator_batch(args, train, t_data, step, "train")
        return _generator_loss(model, batch, _noise(args, "noise", step))

    step = run_steps(
        args,
        "generator",
        args.generator_steps,
        step,
        loss_of,
        optimizer,
        scheduler,
        ("val_loss", validation_loss),
        snapshot,
        history,
    )
    save_checkpoint(
        args.out / "grasp-flow.pt",
        model,
        extra={"dataset": str(args.dataset), "steps": step, "train_objects": len(t_data[0])},
    )
    out = {**snapshot(step), "stage": "samples", "step": 0}
    for key in ("optimizer", "scheduler"):
        out.pop(key)
    save_state(args, out)
    return out


# --------------------------------------------------------------------------------------------
# Stage 2: the generator's own samples, labelled on the full meshes
# --------------------------------------------------------------------------------------------


def sample_objects(args: Args) -> list[tuple[Any, str]]:
    """``(record, split)`` of the objects whose samples train the ranker (seeded choice)."""
    n_val = max(1, args.ranker_objects // 10)
    chosen = []
    for split, count in (("train", args.ranker_objects - n_val), ("validation", n_val)):
        records = open_dataset(args, split).records
        rng = np.random.default_rng(object_seed(args.seed, f"ranker-objects:{split}"))
        order = rng.permutation(len(records))[:count]
        chosen.extend((records[i], split) for i in sorted(order))
    return chosen


def object_samples(args: Args, record: Any) -> dict[str, np.ndarray]:
    """One object's generated, snapped and labelled samples (stage 2)."""
    from baselines.cloud_predictor import PAPER_FORCE_CLOSURE
    from baselines.flow_predictor import FlowPredictor
    from dataset_gen.objects.grasp_object import load_object
    from dg16m_env.evaluators.fce import REASONS, fce_verdicts
    from dg16m_env.subjects.cloud_observation import CloudTrack, cloud_observation

    obj = load_object(record.mesh, object_id=record.object_id, scale=1.0, allow_any_size=True)
    observation = cloud_observation(obj, CloudTrack(camera_seed=0, noise_seed=0))
    predictor = FlowPredictor(
        generator_checkpoint=str(args.out / "grasp-flow.pt"),
        n_points=args.n_points,
        check_points=args.check_points,
        seed=args.seed,
        threads=args.threads,
    )
    cloud, candidates, passed, rng = predictor.candidates(observation)
    pool = np.arange(candidates.n) if args.ranker_pairs == "all" else np.flatnonzero(passed)
    take = np.sort(rng.choice(pool, min(pool.size, args.ranker_samples), replace=False))
    poses = candidates.poses[take]
    codes = fce_verdicts(obj, poses, PAPER_FORCE_CLOSURE)[0] if len(take) else np.zeros(0, np.int8)
    return {
        "cloud": cloud.points.astype(np.float32),
        "poses": poses.astype(np.float32).reshape(-1, 2, 4, 4),
        "cloud_force_closure": passed[take],
        "label": codes == REASONS.index("pass"),
        "codes": codes,
    }


def make_samples(args: Args, state: dict[str, Any]) -> dict[str, Any]:
    """Stage 2 (module docstring): one file per object, done objects skipped on a rerun."""
    import io

    folder = args.out / "samples"
    folder.mkdir(parents=True, exist_ok=True)
    chosen = sample_objects(args)
    for record, split in progress_bar(chosen, desc="samples", unit="object"):
        file = folder / f"{record.object_id}.npz"
        if file.is_file():
            continue
        arrays = object_samples(args, record)
        buffer = io.BytesIO()
        np.savez(buffer, split=np.array(split), **arrays)
        write_bytes_atomic(file, buffer.getvalue())
    out = {**state, "stage": "ranker", "step": 0}
    save_state(args, out)
    return out


# --------------------------------------------------------------------------------------------
# Stage 3: the ranker
# --------------------------------------------------------------------------------------------


def load_samples(args: Args) -> dict[str, list[dict[str, np.ndarray]]]:
    """Stage 2's samples by split, one dict per object with at least one sample: ``cloud (P,
    3)``, ``poses (S, 2, 4, 4)``, ``label (S,)``."""
    by_split: dict[str, list[dict[str, np.ndarray]]] = {}
    for record, split in sample_objects(args):
        with np.load(args.out / "samples" / f"{record.object_id}.npz") as data:
            if len(data["label"]):
                by_split.setdefault(split, []).append(
                    {k: data[k] for k in ("cloud", "poses", "label")}
                )
    if not by_split.get("train"):
        raise TrainingArgumentsError(
            f"{args.out / 'samples'}: expected generated samples of train objects, found none"
        )
    return by_split


def ranker_batch(
    args: Args, objects: list[dict[str, np.ndarray]], step: int
) -> tuple[np.ndarray, ...]:
    """``(clouds (B, P, 3), poses (B, G, 2, 4, 4), labels (B, G))`` of ranker step ``step``:
    half passing samples where an object has both kinds."""
    rng = np.random.default_rng(object_seed(args.seed, f"ranker-batch:{step}"))
    b, g = args.ranker_batch_objects, args.ranker_grasps
    chosen = rng.choice(len(objects), b, replace=len(objects) < b)
    clouds, poses, labels = [], [], []
    for o in chosen:
        cloud = objects[o]["cloud"]  # fewer points where the cameras saw fewer: repeated
        if len(cloud) != args.n_points:
            cloud = cloud[rng.choice(len(cloud), args.n_points, replace=len(cloud) < args.n_points)]
        label = objects[o]["label"]
        pos, neg = np.flatnonzero(label), np.flatnonzero(~label)
        if pos.size and neg.size:
            pick = np.concatenate([rng.choice(pos, g // 2), rng.choice(neg, g - g // 2)])
        else:
            pick = rng.choice(len(label), g)
        clouds.append(cloud)
        poses.append(objects[o]["poses"][pick])
        labels.append(label[pick])
    return np.stack(clouds), np.stack(poses), np.stack(labels)


def train_ranker(args: Args, state: dict[str, Any]) -> dict[str, Any]:
    """Stage 3 (module docstring); returns the final state."""
    import torch

    from baselines.da2_labels import roc_auc
    from baselines.dual_pointnet_gpd import DualPointNetGPD, DualPointNetGPDConfig
    from baselines.grasp_geometry import save_checkpoint

    data = load_samples(args)
    train, val = data["train"], data.get("validation")
    model = DualPointNetGPD(DualPointNetGPDConfig(seed=args.seed))
    optimizer = torch.optim.Adam(model.parameters(), lr=args.learning_rate)
    step = int(state.get("step", 0))
    if "ranker" in state:
        model.load_state_dict(state["ranker"])
        optimizer.load_state_dict(state["ranker_optimizer"])
    history: list[dict[str, Any]] = state.setdefault("history", [])

    def validation_auc() -> float:
        if not val:
            return float("nan")
        scores = []
        with torch.no_grad():
            for o in val:
                scores.append(model(torch.from_numpy(o["cloud"]), torch.from_numpy(o["poses"])))
        labels = np.concatenate([o["label"] for o in val])
        auc = roc_auc(torch.cat(scores).numpy(), labels)
        return float("nan") if auc is None else float(auc)  # None: one class only

    def snapshot(step: int) -> dict[str, Any]:
        return {
            **state,
            "stage": "ranker",
            "step": step,
            "ranker": model.state_dict(),
            "ranker_optimizer": optimizer.state_dict(),
        }

    def loss_of(step: int) -> Any:
        clouds, poses, labels = ranker_batch(args, train, step)
        logits = model.forward_batch(torch.from_numpy(clouds), torch.from_numpy(poses))
        return torch.nn.functional.binary_cross_entropy_with_logits(
            logits, torch.from_numpy(labels.astype(np.float32))
        )

    step = run_steps(
        args,
        "ranker",
        args.ranker_steps,
        step,
        loss_of,
        optimizer,
        None,
        ("val_auc", validation_auc),
        snapshot,
        history,
    )
    rates = {
        split: {
            "objects": len(objects),
            "samples": int(sum(o["label"].size for o in objects)),
            "passing": float(np.mean(np.concatenate([o["label"] for o in objects]))),
        }
        for split, objects in data.items()
    }
    save_checkpoint(
        args.out / "grasp-flow-ranker.pt",
        model,
        extra={"dataset": str(args.dataset), "steps": step, "sample_rates": json.dumps(rates)},
    )
    out = {**snapshot(step), "stage": "done"}
    save_state(args, out)
    return out


def plot_curves(path: Path, history: list[dict[str, Any]]) -> None:
    """The generator's losses and the ranker's loss and validation AUC against steps (PNG)."""
    from matplotlib.figure import Figure

    figure = Figure(figsize=(10, 3.6))
    left, right = figure.subplots(1, 2)
    gen = [h for h in history if h["stage"] == "generator"]
    rank = [h for h in history if h["stage"] == "ranker"]
    for key in ("train_loss", "val_loss"):
        left.plot([h["step"] for h in gen], [h[key] for h in gen], label=key.replace("_", " "))
    left.set(title="generator (flow matching)", xlabel="step", ylabel="velocity MSE")
    left.legend()
    right.plot([h["step"] for h in rank], [h["train_loss"] for h in rank], label="train BCE")
    right.plot([h["step"] for h in rank], [h["val_auc"] for h in rank], label="validation AUC")
    right.set(title="ranker (own samples, full-mesh labels)", xlabel="step")
    right.legend()
    figure.tight_layout()
    with atomic_path(path) as tmp:
        figure.savefig(tmp, format="png", dpi=110)


def main(args: Args | None = None) -> dict[str, Any]:
    args = args or parse_args(Args, __doc__.split("\n\n")[0])
    import torch

    torch.set_num_threads(args.threads)
    for name in ("n_points", "grasps_per_batch", "grasps_per_object"):
        if getattr(args, name) < 1:
            raise TrainingArgumentsError(
                f"--{name.replace('_', '-')}: expected >= 1, found {getattr(args, name)}"
            )
    if args.ranker_pairs not in RANKER_PAIRS:
        raise TrainingArgumentsError(
            f"--ranker-pairs: expected one of {RANKER_PAIRS}, found {args.ranker_pairs!r}"
        )
    if args.grasps_per_batch > args.grasps_per_object:
        raise TrainingArgumentsError(
            "expected --grasps-per-batch <= --grasps-per-object, found "
            f"{args.grasps_per_batch} > {args.grasps_per_object}"
        )
    args.out.mkdir(parents=True, exist_ok=True)
    state = load_state(args) or {"stage": "generator", "step": 0, "history": []}
    previous = signal.signal(signal.SIGTERM, _on_signal)
    started = time.monotonic()
    try:
        stages = {"generator": train_generator, "samples": make_samples, "ranker": train_ranker}
        while state["stage"] != "done":
            state = stages[state["stage"]](args, state)
    except (_StopRequestedError, KeyboardInterrupt):
        print(f"stopped; rerun the same command to resume from {args.out / 'state.pt'}")
        raise SystemExit(130) from None
    finally:
        signal.signal(signal.SIGTERM, previous)
    history = state["history"]
    finite = [
        {k: None if isinstance(v, float) and np.isnan(v) else v for k, v in h.items()}
        for h in history
    ]
    write_json_atomic(args.out / "history.json", {"args": _identity(args), "history": finite})
    plot_curves(args.out / "curves.png", history)
    print(
        f"done in {time.monotonic() - started:.0f} s: {args.out / 'grasp-flow.pt'}, "
        f"{args.out / 'grasp-flow-ranker.pt'}"
    )
    return state


if __name__ == "__main__":
    main()
