"""Offscreen pictures of objects and dual grasps (matplotlib's Agg canvas: no display, no GL).

Figures are built on :class:`matplotlib.figure.Figure` with an Agg canvas: no pyplot state and no
``matplotlib.use``, so importing this module never changes the caller's backend.

Grippers are drawn as line skeletons of the gripper model (palm stem, cross bar, fingers, and a
short bar at the contact depth); the two hands of one dual grasp share a colour and are joined by
a dashed line between their contact midpoints.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import matplotlib
import numpy as np
import trimesh
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator
from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection
from mpl_toolkits.mplot3d.axes3d import Axes3D

from dataset_gen.grasps.gripper import GripperModel, get_gripper, transform_points
from dg16m_core.figures import new_figure, save_png

MAX_DRAWN_FACES = 40_000
"""Meshes with more faces are drawn from a deterministic subset of this many faces."""

_LIGHT = np.array([0.4, -0.5, 0.75]) / np.linalg.norm([0.4, -0.5, 0.75])


def _mesh_collection(
    mesh: trimesh.Trimesh,
    *,
    color: tuple[float, float, float] = (0.72, 0.74, 0.78),
    alpha: float = 0.55,
) -> Poly3DCollection:
    faces = np.asarray(mesh.faces)
    normals = np.asarray(mesh.face_normals)
    if len(faces) > MAX_DRAWN_FACES:
        keep = np.random.default_rng(0).choice(len(faces), MAX_DRAWN_FACES, replace=False)
        keep.sort()
        faces, normals = faces[keep], normals[keep]
    shade = 0.45 + 0.55 * np.abs(normals @ _LIGHT)
    colors = np.clip(np.asarray(color)[None, :] * shade[:, None], 0, 1)
    colors = np.concatenate([colors, np.full((len(colors), 1), alpha)], axis=1)
    collection = Poly3DCollection(np.asarray(mesh.vertices)[faces], linewidths=0.0)
    collection.set_facecolor(colors)
    return collection


def _setup_axes(
    ax: Axes3D, mesh: trimesh.Trimesh, extra_points: np.ndarray | None, view: tuple[float, float]
) -> None:
    points = np.asarray(mesh.vertices)
    if extra_points is not None and len(extra_points):
        points = np.concatenate([points, extra_points.reshape(-1, 3)])
    lo, hi = points.min(axis=0), points.max(axis=0)
    centre = (lo + hi) / 2
    half = max(float((hi - lo).max()) / 2, 1e-3) * 1.05
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elev=view[0], azim=view[1])
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):  # three ticks a side: labels that do not touch
        axis.set_major_locator(MaxNLocator(nbins=3))
    ax.set_xlabel("x (m)", fontsize=7, labelpad=-2)
    ax.set_ylabel("y (m)", fontsize=7, labelpad=-2)
    ax.set_zlabel("z (m)", fontsize=7, labelpad=-2)
    ax.tick_params(labelsize=6, pad=0)


def select_pairs(passed: np.ndarray, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Indices of up to ``n // 2`` passing and ``n - n // 2`` failing pairs (sorted, seeded).

    If one class has fewer pairs, the other fills the remaining slots.
    """
    rng = np.random.default_rng(seed)
    passing = np.flatnonzero(passed)
    failing = np.flatnonzero(~passed)
    n_pass = min(len(passing), max(n // 2, n - len(failing)))
    n_fail = min(len(failing), n - n_pass)
    pick_pass = np.sort(rng.choice(passing, n_pass, replace=False)) if n_pass else passing[:0]
    pick_fail = np.sort(rng.choice(failing, n_fail, replace=False)) if n_fail else failing[:0]
    return pick_pass, pick_fail


def render_dual_grasps(
    mesh: trimesh.Trimesh,
    grasps: np.ndarray,
    passed: np.ndarray,
    out: str | os.PathLike[str],
    *,
    gripper: str | GripperModel = "robotiq_2f85",
    contact_points: np.ndarray | None = None,
    n: int = 20,
    seed: int = 0,
    title: str = "",
    view: tuple[float, float] = (25.0, -60.0),
    dpi: int = 130,
) -> Path:
    """Render ``n`` dual grasps on ``mesh`` to a PNG: passing pairs left, failing pairs right.

    Args:
        mesh: the object in the grasps' frame (m).
        grasps: (N, 2, 4, 4) dual grasp poses (dg16m grasp frame).
        passed: (N,) bool force-closure verdicts.
        out: PNG path (written atomically).
        gripper: model whose skeleton is drawn.
        contact_points: optional (N, 4, 3) contacts, drawn as dots.
        n: total number of pairs drawn, split between the panels by :func:`select_pairs`
            (``n // 2`` passing and the rest failing; a class with fewer pairs leaves its slots
            to the other).
        seed: which pairs are drawn.
        view: (elevation, azimuth) in degrees.
    """
    model = get_gripper(gripper)
    grasps = np.asarray(grasps, dtype=np.float64)
    passed = np.asarray(passed, dtype=bool)
    pick_pass, pick_fail = select_pairs(passed, n, seed)
    skeleton = model.skeleton().reshape(-1, 3)
    fig = new_figure(13, 6.5)
    panels = [
        (pick_pass, "Greens", f"force closure: pass ({len(pick_pass)} of {int(passed.sum())})"),
        (pick_fail, "Reds", f"force closure: fail ({len(pick_fail)} of {int((~passed).sum())})"),
    ]
    drawn = [transform_points(grasps[i], skeleton).reshape(-1, 3) for i in (*pick_pass, *pick_fail)]
    extra = np.concatenate(drawn) if drawn else None
    for column, (indices, cmap, label) in enumerate(panels):
        ax = fig.add_subplot(1, 2, column + 1, projection="3d")
        ax.add_collection3d(_mesh_collection(mesh))
        for rank, index in enumerate(indices):
            color = matplotlib.colormaps[cmap](0.55 + 0.4 * rank / max(len(indices) - 1, 1))
            points = None if contact_points is None else np.asarray(contact_points[index])
            _draw_dual_grasp(ax, model, grasps[index], skeleton, color, points)
        _setup_axes(ax, mesh, extra, view)  # same limits in both panels
        ax.set_title(label, fontsize=10)
    _annotate_dual_grasps(fig, title or f"{len(grasps)} dual grasps, gripper {model.name}")
    return save_png(fig, out, dpi=dpi)


def _draw_dual_grasp(
    ax: Axes3D,
    model: GripperModel,
    poses: np.ndarray,
    skeleton: np.ndarray,
    color: tuple[float, ...],
    contact_points: np.ndarray | None,
) -> None:
    """Both hands' skeletons of one dual grasp (2, 4, 4), a dashed line joining their contact
    midpoints and the (4, 3) contact points when given."""
    segments = transform_points(poses, skeleton).reshape(2, -1, 2, 3)
    lines = Line3DCollection(segments.reshape(-1, 2, 3), colors=[color], linewidths=1.6)
    ax.add_collection3d(lines)
    mids = transform_points(poses, [[0.0, model.contact_depth, 0.0]])[:, 0]
    ax.plot(*mids.T, linestyle="--", color=color, linewidth=0.8)
    if contact_points is not None:
        ax.scatter(*contact_points.T, color="black", s=6, depthshade=False)


def _annotate_dual_grasps(fig: Figure, title: str) -> None:
    fig.suptitle(title, fontsize=11, y=0.985)
    fig.text(
        0.5,
        0.015,
        "lines: gripper skeletons (palm, fingers, bar at the contact depth); "
        "dashed: the two hands of one dual grasp; dots: stored contact points",
        ha="center",
        fontsize=8,
        color="0.3",
    )
    fig.tight_layout(rect=(0.0, 0.03, 1.0, 0.95))


def render_objects(
    items: Sequence[tuple[str, trimesh.Trimesh]],
    out: str | os.PathLike[str],
    *,
    columns: int = 5,
    view: tuple[float, float] = (25.0, -60.0),
    dpi: int = 100,
) -> Path:
    """Contact sheet of ``(label, mesh)`` items, one small 3D view each, as a PNG."""
    if not items:
        raise ValueError("render_objects: expected at least one object, found none")
    columns = max(1, min(columns, len(items)))
    rows = -(-len(items) // columns)
    fig = new_figure(3.0 * columns, 3.0 * rows)
    for i, (label, mesh) in enumerate(items):
        ax = fig.add_subplot(rows, columns, i + 1, projection="3d")
        ax.add_collection3d(_mesh_collection(mesh, color=(0.55, 0.65, 0.85), alpha=1.0))
        _setup_axes(ax, mesh, None, view)
        ext = np.asarray(mesh.extents)
        ax.set_title(f"{label}\n{ext[0]:.2f} x {ext[1]:.2f} x {ext[2]:.2f} m", fontsize=8)
    fig.tight_layout()
    return save_png(fig, out, dpi=dpi)


def render_grasp_sheet(
    items: Sequence[tuple[str, trimesh.Trimesh, np.ndarray]],
    out: str | os.PathLike[str],
    *,
    gripper: str | GripperModel = "panda",
    columns: int = 4,
    title: str = "",
    view: tuple[float, float] = (25.0, -60.0),
    dpi: int = 100,
) -> Path:
    """Contact sheet of objects, each with a few of its passing dual grasps, as a PNG.

    Args:
        items: ``(label, mesh, poses)``: the panel's title, the object (object frame, m) and
            (k, 2, 4, 4) dual grasps drawn on it (k may be 0).
        out: PNG path (written atomically).
        gripper: the model whose skeleton is drawn.
        columns: panels per row.
    """
    if not items:
        raise ValueError("render_grasp_sheet: expected at least one object, found none")
    model = get_gripper(gripper)
    skeleton = model.skeleton().reshape(-1, 3)
    columns = max(1, min(columns, len(items)))
    rows = -(-len(items) // columns)
    fig = new_figure(3.4 * columns, 3.4 * rows + 0.6)
    for i, (label, mesh, poses) in enumerate(items):
        ax = fig.add_subplot(rows, columns, i + 1, projection="3d")
        ax.add_collection3d(_mesh_collection(mesh, color=(0.6, 0.68, 0.85), alpha=0.6))
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 2, 4, 4)
        for rank, pose in enumerate(poses):
            color = matplotlib.colormaps["tab10"](rank % 10)
            _draw_dual_grasp(ax, model, pose, skeleton, color, None)
        drawn = transform_points(poses, skeleton).reshape(-1, 3) if len(poses) else None
        _setup_axes(ax, mesh, drawn, view)
        ax.set_title(label, fontsize=8)
    if title:
        fig.suptitle(title, fontsize=11)
    fig.tight_layout(rect=(0.0, 0.0, 1.0, 0.96 if title else 1.0), h_pad=2.5)
    return save_png(fig, out, dpi=dpi)
