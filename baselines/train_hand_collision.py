"""Train the hand-collision check of the partial-cloud predictors (:mod:`baselines.hand_collision`).

Reads top to bottom: for each procedural training object (``dataset_gen.sources.procedural`` train split,
never a benchmark seed), the two-camera cloud of :data:`baselines.cloud_predictor.PARTIAL_SAMPLER`'s
predictor, its dual candidates, every open hand's features (:func:`hand_features`) and its truth
(:func:`dg16m_env.physics.trial_protocol.open_hand_penetration` deeper than the protocol's
``invalid_penetration``: the evaluator's own test on the simulated parts); then an MLP trained
with a class-weighted logistic loss, the last ``val_objects`` objects held out for the loss and
AUC it prints; the checkpoint is written atomically.

    python -m baselines.train_hand_collision --features runs/hand_collision_features.npz

The default run (500 objects, 50 of each benchmark family) takes about 3 minutes for the
features on 2 cores and 1 minute per epoch; the held-out loss is lowest after the first epoch
(later epochs fit the training objects), and that epoch is kept.
"""

from __future__ import annotations

import dataclasses
import multiprocessing
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from baselines.cloud_grasps import cloud_dual_candidates
from baselines.cloud_predictor import SEED_PREFIX, cgdf_partial_predictor
from baselines.da2_labels import roc_auc
from baselines.hand_collision import DEPTH_SCALE, GRID, hand_features, make_net, n_features
from baselines.sb3_common import parse_args
from dataset_gen.sources.object_source import object_seed
from dataset_gen.sources.procedural import FAMILIES, N_BENCHMARK_FAMILIES, make_procedural_object
from dg16m_core.atomic import atomic_path


@dataclass(frozen=True)
class Args:
    """Arguments (``--name value`` on the command line)."""

    objects: int = 500
    """Procedural training objects, families in turn (the benchmark's 10)."""
    first_seed: int = 0
    """Seed of each family's first object (train seeds are below the benchmark's)."""
    seed: int = 0
    """Seed of the clouds and candidates (per object, as the predictor's) and of training."""
    val_objects: int = 50
    """The last this-many objects are held out to report the loss and AUC."""
    epochs: int = 8
    """Training epochs; the epoch with the lowest held-out loss is kept."""
    batch: int = 512
    lr: float = 3e-4
    weight_decay: float = 1e-4
    workers: int = 2
    out: str = "baselines/checkpoints/hand-collision.pt"
    features: str = ""
    """An .npz file to keep the hands' features and truth in: read when it exists and was made
    with the same objects, else written (empty: not kept)."""


def object_hands(spec: tuple[str, int, int]) -> tuple[str, np.ndarray, np.ndarray]:
    """One training object's hands: ``(object id, features (H, F) float32, starts_inside (H,)
    bool)``; ``H = 2 x`` its dual candidates."""
    from dg16m_core.parameters import PROTOCOL
    from dg16m_env.physics.scene import compile_scene
    from dg16m_env.physics.trial_protocol import open_hand_penetration
    from dg16m_env.subjects.observation import object_observation

    family, object_seed_, seed = spec
    obj = make_procedural_object(family, object_seed_)
    predictor = cgdf_partial_predictor
    rng = np.random.default_rng(object_seed(seed, SEED_PREFIX + obj.object_id))
    cloud, views = predictor.observe(object_observation(obj), rng)
    cands = cloud_dual_candidates(cloud, predictor.sampler, rng=rng)
    if cands.n == 0 or views is None:
        return obj.object_id, np.zeros((0, n_features()), np.float32), np.zeros(0, bool)
    features = hand_features(cloud, views, cands.poses).reshape(2 * cands.n, -1)
    depth = open_hand_penetration(compile_scene(obj), cands.poses).max(axis=2)  # (N, 2)
    return obj.object_id, features, (depth > PROTOCOL.invalid_penetration).reshape(-1)


def cached_hands(path: Path, specs: list[tuple[str, int, int]]) -> list | None:
    """The hands kept in ``path`` by :func:`save_hands` for the same ``specs``, else ``None``."""
    if not path.is_file():
        return None
    with np.load(path) as data:
        if data["specs"].tolist() != [list(map(str, s)) for s in specs]:
            return None
        ids, sizes = data["ids"].tolist(), data["sizes"]
        features = np.split(data["features"], np.cumsum(sizes)[:-1])
        truth = np.split(data["truth"], np.cumsum(sizes)[:-1])
    print(f"features of {len(ids)} objects read from {path}")
    return list(zip(ids, features, truth, strict=True))


def save_hands(path: Path, specs: list[tuple[str, int, int]], hands: list) -> None:
    """Keep the hands' features and truth in ``path`` (atomically)."""
    with atomic_path(path) as tmp, open(tmp, "wb") as handle:
        np.savez(
            handle,
            specs=np.array([list(map(str, s)) for s in specs]),
            ids=np.array([h[0] for h in hands]),
            sizes=np.array([len(h[2]) for h in hands]),
            features=np.concatenate([h[1] for h in hands]),
            truth=np.concatenate([h[2] for h in hands]),
        )


def main(args: Args) -> None:
    import torch

    from dg16m_core.progress import progress_bar

    families = FAMILIES[:N_BENCHMARK_FAMILIES]
    specs = [
        (families[i % len(families)], args.first_seed + i // len(families), args.seed)
        for i in range(args.objects)
    ]
    hands = cached_hands(Path(args.features), specs) if args.features else None
    if hands is None:
        start = time.perf_counter()
        with multiprocessing.get_context("spawn").Pool(args.workers) as pool:
            hands = list(
                progress_bar(pool.imap(object_hands, specs), total=len(specs), desc="objects")
            )
        print(f"features of {len(hands)} objects in {time.perf_counter() - start:.0f} s")
        if args.features:
            save_hands(Path(args.features), specs, hands)

    def stack(part: list) -> tuple[torch.Tensor, torch.Tensor]:
        x = np.concatenate([h[1] for h in part])
        y = np.concatenate([h[2] for h in part])
        return torch.from_numpy(x), torch.from_numpy(y.astype(np.float32))

    n_val = min(args.val_objects, len(hands) - 1)
    x_train, y_train = stack(hands[: len(hands) - n_val])
    x_val, y_val = stack(hands[len(hands) - n_val :])
    positive = float(y_train.mean())
    print(
        f"{len(y_train)} training hands ({100 * positive:.1f}% start inside), {len(y_val)} held out"
    )

    torch.manual_seed(args.seed)
    net = make_net(x_train.shape[1])
    optimiser = torch.optim.AdamW(net.parameters(), lr=args.lr, weight_decay=args.weight_decay)
    loss_fn = torch.nn.BCEWithLogitsLoss(pos_weight=torch.tensor((1 - positive) / positive))
    generator = torch.Generator().manual_seed(args.seed)
    best: tuple[float, int, dict, float | None] | None = None
    for epoch in range(args.epochs):
        net.train()
        order = torch.randperm(len(y_train), generator=generator)
        for batch in order.split(args.batch):
            optimiser.zero_grad()
            loss_fn(net(x_train[batch]), y_train[batch]).backward()
            optimiser.step()
        net.eval()
        with torch.no_grad():
            logits = net(x_val)
            val_loss = float(loss_fn(logits, y_val))
        val_auc = roc_auc(logits.numpy(), y_val.numpy() > 0.5)
        print(f"epoch {epoch + 1}: held-out loss {val_loss:.4f}, AUC {_auc_text(val_auc)}")
        if best is None or val_loss < best[0]:
            state = {k: v.detach().clone() for k, v in net.state_dict().items()}
            best = (val_loss, epoch + 1, state, val_auc)
    assert best is not None  # epochs >= 1
    val_loss, best_epoch, state, val_auc = best
    print(f"kept epoch {best_epoch} (held-out loss {val_loss:.4f}, AUC {_auc_text(val_auc)})")

    metadata = {
        "kind": "hand-collision",
        "n_features": n_features(),
        "grid": GRID,
        "depth_scale": DEPTH_SCALE,
        "objects": [h[0] for h in hands],
        "val_objects": n_val,
        "held_out_auc": val_auc,
        "held_out_loss": val_loss,
        "epoch": best_epoch,
        "args": dataclasses.asdict(args),
    }
    with atomic_path(Path(args.out)) as tmp:
        torch.save({"state_dict": state, "metadata": metadata}, tmp)
    print(f"wrote {args.out} (held-out AUC {_auc_text(val_auc)})")


def _auc_text(value: float | None) -> str:
    """An AUC for printing (``n/a`` when the held-out hands hold one class only)."""
    return "n/a" if value is None else f"{value:.4f}"


if __name__ == "__main__":
    main(parse_args(Args, __doc__.split("\n\n")[0]))
