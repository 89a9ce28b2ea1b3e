"""Training loader throughput on one core: samples/s a training loop gets from a dataset folder,
against reading the same grasp files' arrays with h5py alone (the floor of any loader).

Streams ``--samples`` samples with :class:`dg16m_env.training.grasp_dataset.DualGraspStream`
through a ``DataLoader`` (batch 256, no worker processes, one torch thread), twice: the first
pass makes each object's cloud (``--cloud full`` or ``partial``) and keeps it, the second reads
it from memory (the steady state of a training run; clouds are cached per object). The
reference reads the grasp arrays of the same objects with h5py in the same run. The target
(issue 54): >= 2,000 samples/s on one core.

    .venv/bin/python bench/dataset_loader.py --dataset runs/dg16m          # a built dataset
    .venv/bin/python bench/dataset_loader.py --objects 24                  # builds a small one
"""

from __future__ import annotations

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np
import torch
from torch.utils.data import DataLoader

from dataset_gen.collection.build import build_dataset
from dataset_gen.collection.recipe import DatasetRecipe
from dataset_gen.collection.splits import Exclusion
from dg16m_env.training.grasp_dataset import DualGraspStream

TARGET = 2000.0


def _stream_rate(stream: DualGraspStream, samples: int) -> tuple[float, int]:
    loader = DataLoader(stream, batch_size=256)
    start, n = time.perf_counter(), 0
    for batch in loader:
        n += len(batch["poses"])
        if n >= samples:
            break
    return n / (time.perf_counter() - start), n


def _raw_rate(stream: DualGraspStream, samples: int) -> float:
    start, n = time.perf_counter(), 0
    for record in stream.records:
        with h5py.File(record.grasps, "r") as f:
            poses = np.asarray(f["grasps/grasps"], dtype=np.float32)
            np.asarray(f["grasps/fc_passing_indices"])
        n += len(poses)
        if n >= samples:
            break
    return n / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--dataset", type=Path, default=None, help="a built dataset folder")
    parser.add_argument("--objects", type=int, default=24, help="objects of the built one")
    parser.add_argument("--samples", type=int, default=60_000)
    parser.add_argument("--cloud", choices=("full", "partial"), default="full")
    parser.add_argument("--points", type=int, default=1024)
    args = parser.parse_args()
    torch.set_num_threads(1)
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.dataset
        if folder is None:
            folder = Path(tmp) / "ds"
            recipe = DatasetRecipe(objects=args.objects, sources=("procedural",))
            build_dataset(folder, recipe, Exclusion(), progress=False, card=False, log=print)
        stream = DualGraspStream(
            folder, splits=("train", "validation"), cloud=args.cloud, n_points=args.points
        )
        first, n = _stream_rate(stream, args.samples)
        steady, _ = _stream_rate(stream, args.samples)
        raw = _raw_rate(stream, n)
    print(f"{len(stream.records)} objects, {n} samples, clouds: {args.cloud} {args.points} points")
    print(f"first pass (clouds made):   {first:10,.0f} samples/s")
    print(f"steady (clouds in memory):  {steady:10,.0f} samples/s")
    print(f"h5py arrays alone:          {raw:10,.0f} samples/s")
    print(
        f"ratio steady / h5py: {steady / raw:.3f}; target >= {TARGET:,.0f}: "
        f"{'met' if steady >= TARGET else 'NOT met'} ({steady / TARGET:.1f}x)"
    )


if __name__ == "__main__":
    main()
