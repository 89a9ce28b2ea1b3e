"""Dataset statistics: counts per object and the paper's Fig. 4 (Q(G) of passing vs failing)."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from dataset_gen.io import manifest_entry_path, read_dg16m, read_manifest
from dg16m_core.errors import GraspFileError
from dg16m_core.figures import new_figure, save_png


@dataclass
class DatasetStats:
    """Per-object numbers of a generated dataset folder.

    Attributes:
        objects: object ids with a readable file, in manifest order.
        failed: object id -> error for objects the generator could not process.
        passing, failing: pairs stored per object.
        candidate_pass_rate: passing candidates / candidates per object (from the counts).
        quality_passing, quality_failing: Q(G) of every stored pair (all objects).
        loss_failing: losses of every stored failing pair (N).
    """

    objects: list[str] = field(default_factory=list)
    failed: dict[str, str] = field(default_factory=dict)
    passing: list[int] = field(default_factory=list)
    failing: list[int] = field(default_factory=list)
    candidate_pass_rate: list[float] = field(default_factory=list)
    quality_passing: np.ndarray = field(default_factory=lambda: np.zeros(0))
    quality_failing: np.ndarray = field(default_factory=lambda: np.zeros(0))
    loss_failing: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def summary(self) -> dict[str, Any]:
        """JSON-ready totals."""
        rate = np.asarray(self.candidate_pass_rate, dtype=float)
        return {
            "objects": len(self.objects),
            "failed_objects": len(self.failed),
            "pairs": int(sum(self.passing) + sum(self.failing)),
            "passing_pairs": int(sum(self.passing)),
            "failing_pairs": int(sum(self.failing)),
            "candidate_pass_rate_mean": float(rate.mean()) if rate.size else None,
            "candidate_pass_rate_min": float(rate.min()) if rate.size else None,
            "candidate_pass_rate_max": float(rate.max()) if rate.size else None,
            "quality_median_passing": float(np.median(self.quality_passing))
            if self.quality_passing.size
            else None,
            "quality_median_failing": float(np.median(self.quality_failing))
            if self.quality_failing.size
            else None,
        }


def collect_stats(folder: str | os.PathLike[str]) -> DatasetStats:
    """Read every ``ok`` object of a generated dataset folder (``manifest.json`` + files).

    Raises:
        GraspFileError: no manifest, a manifest of another kind, or an unreadable file.
    """
    root = Path(folder)
    manifest = read_manifest(root)
    if manifest["kind"] != "grasps":
        raise GraspFileError(
            f"{root}/manifest.json: expected a grasp dataset (kind 'grasps'), found {manifest['kind']!r}"
        )
    stats = DatasetStats()
    q_pass: list[np.ndarray] = []
    q_fail: list[np.ndarray] = []
    losses: list[np.ndarray] = []
    for object_id, entry in manifest["entries"].items():
        if entry["status"] != "ok":
            stats.failed[object_id] = entry.get("error", "")
            continue
        data = read_dg16m(manifest_entry_path(root, manifest, object_id, "grasps"))
        stats.objects.append(object_id)
        stats.passing.append(int(data.passing_indices.size))
        stats.failing.append(int(data.failed_indices.size))
        counts = data.metadata.get("counts", {})
        candidates = counts.get("pairs_remaining", 0)
        stats.candidate_pass_rate.append(
            counts.get("passing", 0) / candidates if candidates else 0.0
        )
        quality = data.extras.get("quality")
        if quality is not None:
            q_pass.append(quality[data.passing_indices])
            q_fail.append(quality[data.failed_indices])
        losses.append(data.loss_values[data.failed_indices])
    if q_pass:
        stats.quality_passing = np.concatenate(q_pass)
        stats.quality_failing = np.concatenate(q_fail)
    if losses:
        stats.loss_failing = np.concatenate(losses)
    return stats


def format_summary(summary: dict[str, Any]) -> list[str]:
    """Lines ``key  value`` of :meth:`DatasetStats.summary` for people: counts as integers,
    rates and qualities with 4 significant digits, missing values as ``-``."""
    lines = []
    for key, value in summary.items():
        if value is None:
            text = "-"
        elif isinstance(value, float):
            text = f"{value:.4g}"
        else:
            text = str(value)
        lines.append(f"{key:26s} {text}")
    return lines


def plot_stats(stats: DatasetStats, out: str | os.PathLike[str]) -> list[Path]:
    """Write ``quality_hist.png`` (Fig. 4), ``passes_per_object.png`` and ``loss_hist.png``.

    Figures are built on :class:`matplotlib.figure.Figure` (no pyplot state, no backend switch).
    """
    root = Path(out)
    root.mkdir(parents=True, exist_ok=True)
    figures = {
        "quality_hist.png": _quality_figure(stats),
        "passes_per_object.png": _passes_figure(stats),
        "loss_hist.png": _loss_figure(stats),
    }
    return [
        save_png(fig, root / name, dpi=120, bbox_inches="tight") for name, fig in figures.items()
    ]


def _figure(width: float, height: float) -> tuple[Figure, Any]:
    fig = new_figure(width, height)
    return fig, fig.add_subplot()


def _quality_figure(stats: DatasetStats) -> Figure:
    fig, ax = _figure(6, 4)
    both = np.concatenate([stats.quality_passing, stats.quality_failing])
    if both.size:
        bins = np.linspace(0.0, float(np.percentile(both, 99.5)) or 1.0, 50)
        ax.hist(stats.quality_passing, bins=bins, alpha=0.6, label="passing", color="tab:green")
        ax.hist(stats.quality_failing, bins=bins, alpha=0.6, label="failing", color="tab:red")
        ax.legend()
    ax.set_xlabel("Q(G) = sqrt(det(G G^T))")
    ax.set_ylabel("dual grasps")
    ax.set_title("Grasp-matrix quality of stored pairs (paper Fig. 4)")
    return fig


#: Up to this many objects the figure names each one; beyond, it shows their distribution.
PASSES_LABELLED_OBJECTS = 40
#: The objects with the fewest passing pairs named beside the distribution of a large dataset.
PASSES_FEWEST = 20


def _passes_figure(stats: DatasetStats) -> Figure:
    """Stored passing and failing pairs per object: one labelled horizontal bar per object
    (readable names) up to :data:`PASSES_LABELLED_OBJECTS` objects; beyond, the distribution of
    pairs per object beside the :data:`PASSES_FEWEST` objects with the fewest passing pairs."""
    count = len(stats.objects)
    if count <= PASSES_LABELLED_OBJECTS:
        fig, ax = _figure(6.5, max(2.5, 1.2 + 0.28 * count))
        _pair_bars(ax, stats.objects, stats.passing, stats.failing)
        ax.set_title(f"Stored pairs per object ({count} objects)")
        return fig
    fig = new_figure(12, max(4.5, 1.2 + 0.28 * PASSES_FEWEST))
    left, right = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    top = max(max(stats.passing, default=0), max(stats.failing, default=0), 1)
    bins = np.linspace(0, top, 31)
    left.hist(stats.passing, bins=bins, alpha=0.6, color="tab:green", label="passing")
    left.hist(stats.failing, bins=bins, alpha=0.6, color="tab:red", label="failing")
    left.set_xlabel("stored pairs of one object")
    left.set_ylabel("objects")
    left.set_title(f"Stored pairs per object ({count} objects)")
    left.legend()
    fewest = sorted(range(count), key=lambda i: (stats.passing[i], stats.objects[i]))[
        :PASSES_FEWEST
    ]
    _pair_bars(
        right,
        [stats.objects[i] for i in fewest],
        [stats.passing[i] for i in fewest],
        [stats.failing[i] for i in fewest],
    )
    right.set_title(f"The {len(fewest)} objects with the fewest passing pairs")
    fig.tight_layout()
    return fig


def _pair_bars(ax: Any, names: list[str], passing: list[int], failing: list[int]) -> None:
    """Horizontal stacked bars (passing, then failing), the first name at the top."""
    y = np.arange(len(names))
    ax.barh(y, passing, color="tab:green", label="passing")
    ax.barh(y, failing, left=passing, color="tab:red", label="failing")
    ax.set_yticks(y, names, fontsize=8)
    ax.set_xlabel("stored pairs")
    ax.grid(axis="x", alpha=0.3)
    if names:
        ax.set_ylim(len(names) - 0.5, -0.5)
        ax.legend(loc="lower right", fontsize=8)


def _loss_figure(stats: DatasetStats) -> Figure:
    fig, ax = _figure(6, 4)
    if stats.loss_failing.size:
        ax.hist(stats.loss_failing, bins=50, color="tab:red")
    ax.set_xlabel("force-closure loss of failing pairs (N)")
    ax.set_ylabel("dual grasps")
    ax.set_title("Loss distribution of stored failing pairs")
    return fig
