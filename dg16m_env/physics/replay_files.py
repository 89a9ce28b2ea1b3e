"""Files of a replayed trial (:mod:`dg16m_env.physics.replay`): :func:`write_strip` writes
frames side by side with their captions (and the slip over time under them) to one PNG,
:func:`write_gif` an animated GIF. Both write atomically; ``dg16m_env.physics.replay`` re-exports
them."""

from __future__ import annotations

import math
import os
import textwrap
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dg16m_core.atomic import atomic_path
from dg16m_core.errors import Dg16mError


class ReplayError(Dg16mError, ValueError):
    """Bad replay input: frame count, image size, output path, row or index."""


def _check_frames(frames: Sequence[np.ndarray]) -> list[np.ndarray]:
    if len(frames) == 0:
        raise ReplayError("frames: expected at least one frame, found none")
    out = [np.asarray(f) for f in frames]
    shape = out[0].shape
    for i, frame in enumerate(out):
        if frame.ndim != 3 or frame.shape[2] not in (3, 4) or frame.shape != shape:
            raise ReplayError(
                f"frames[{i}]: expected an (H, W, 3) image like frames[0] {shape}, found "
                f"{frame.shape}"
            )
    return [np.clip(f, 0, 255).astype(np.uint8) if f.dtype != np.uint8 else f for f in out]


def write_strip(
    frames: Sequence[np.ndarray],
    captions: Sequence[str],
    path: str | os.PathLike[str],
    *,
    title: str = "",
    columns: int | None = None,
    dpi: int = 100,
    curve: Mapping[str, Any] | None = None,
) -> Path:
    """Write frames side by side with a caption under each, to one PNG (atomically); more than
    four in a grid of 4, 3 or 5 columns, the first that leaves no cell empty (4 when none
    does). ``curve`` (:func:`~dg16m_env.physics.replay.slip_curve`): the slip over time drawn
    under the frames, with the protocol's bound, the phases and the frames' times marked.
    Returns the path."""
    frames = _check_frames(frames)
    if len(captions) != len(frames):
        raise ReplayError(
            f"captions: expected one per frame ({len(frames)}), found {len(captions)}"
        )
    from dg16m_core.figures import new_figure, save_png

    n = len(frames)
    if not columns:
        columns = n if n <= 4 else next((c for c in (4, 3, 5) if n % c == 0), 4)
    rows = math.ceil(n / columns)
    height, width = frames[0].shape[:2]
    fig_w = columns * width / dpi
    if title:  # wrapped to the figure's width (about 7 px per character at 10 pt, 100 dpi)
        title = textwrap.fill(title, max(20, int(fig_w * dpi / 7.5)))
    caption_in = 0.3
    title_in = (0.2 + 0.2 * (title.count("\n") + 1)) if title else 0.0
    curve_in = 2.2 if curve is not None else 0.0
    fig_h = rows * (height / dpi + caption_in) + title_in + curve_in
    fig = new_figure(fig_w, fig_h, dpi=dpi)
    if curve is not None:
        _draw_curve(fig, curve, (0.6 / fig_w, 0.55 / fig_h, 1 - 0.8 / fig_w, 1.3 / fig_h))
    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]
    for i, (frame, text) in enumerate(zip(frames, captions, strict=True)):
        r, c = divmod(i, columns)
        bottom = fig_h - title_in - (r + 1) * (height / dpi + caption_in) + caption_in
        ax = fig.add_axes((c / columns, bottom / fig_h, 1.0 / columns, (height / dpi) / fig_h))
        ax.imshow(frame, interpolation="nearest")
        ax.set_xticks([])
        ax.set_yticks([])
        for spine in ax.spines.values():  # a thin frame: neighbouring pictures stay apart
            spine.set_edgecolor("0.55")
            spine.set_linewidth(1.5)
        label = ax.text(
            0.5,
            -caption_in * 0.45 / (height / dpi),
            text,
            transform=ax.transAxes,
            ha="center",
            va="center",
            fontsize=9,
            family="monospace",
        )
        drawn = label.get_window_extent(renderer=renderer).width
        if drawn > 0.96 * width:  # shrink to fit under its frame
            label.set_fontsize(max(4.0, 9.0 * 0.96 * width / drawn))
    if title:
        fig.text(0.5, 1.0 - title_in * 0.5 / fig_h, title, ha="center", va="center", fontsize=10)
    return save_png(fig, path, dpi=dpi, facecolor="white")


def _draw_curve(fig: Any, curve: Mapping[str, Any], box: tuple[float, ...]) -> None:
    """The slip over time (see :func:`write_strip`) in ``box`` (figure fractions)."""
    ax = fig.add_axes(box)
    t = np.asarray(curve["t"], dtype=np.float64)
    ax.plot(t, curve["slip_mm"], color="black", linewidth=1.2, label="slip at the grasp centres")
    ax.axhline(curve["limit_mm"], color="tab:red", linestyle="--", linewidth=1, label="bound")
    for start, name in curve["phases"]:
        ax.axvline(start, color="0.8", linewidth=0.6, zorder=0)
        ax.text(
            start,
            1.0,
            f" {name}",
            transform=ax.get_xaxis_transform(),
            fontsize=6,
            rotation=90,
            va="top",
            ha="left",
            color="0.4",
        )
    for i, when in enumerate(curve["frames_t"]):
        ax.axvline(
            when,
            color="tab:blue",
            alpha=0.5,
            linewidth=1.5,
            zorder=1,
            label="frames above" if i == 0 else None,
        )
    slip = np.asarray(curve["slip_mm"], dtype=np.float64)
    finite = slip[np.isfinite(slip)]  # a trial that blew up ends in NaN
    top = max(float(finite.max()) if finite.size else 0.0, curve["limit_mm"])
    ax.set_ylim(0, 1.15 * top if top > 0 else 1.0)
    ax.set_xlim(float(t[0]), float(t[-1]) if t[-1] > t[0] else float(t[0]) + 1.0)
    ax.set_xlabel("time (s)", fontsize=8)
    ax.set_ylabel("slip (mm)", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.legend(loc="center left", fontsize=7)


def write_gif(
    frames: Sequence[np.ndarray],
    path: str | os.PathLike[str],
    fps: float = 10,
    *,
    captions: Sequence[str] | None = None,
) -> Path:
    """Write frames as an animated GIF (looping, ``fps`` frames per second; atomically), with
    ``captions`` drawn on a white band under each frame when given. Returns the path."""
    from PIL import Image, ImageDraw

    frames = _check_frames(frames)
    if not (isinstance(fps, (int, float)) and math.isfinite(fps) and fps > 0):
        raise ReplayError(f"fps: expected a positive number, found {fps!r}")
    if captions is not None and len(captions) != len(frames):
        raise ReplayError(
            f"captions: expected one per frame ({len(frames)}), found {len(captions)}"
        )
    images = []
    for i, frame in enumerate(frames):
        image = Image.fromarray(frame[..., :3])
        if captions is not None:
            band = 22
            canvas = Image.new("RGB", (image.width, image.height + band), "white")
            canvas.paste(image, (0, 0))
            ImageDraw.Draw(canvas).text((6, image.height + 5), captions[i], fill="black")
            image = canvas
        images.append(image)
    out = Path(path)
    with atomic_path(out) as tmp:
        images[0].save(
            tmp,
            format="GIF",
            save_all=True,
            append_images=images[1:],
            duration=max(20, round(1000.0 / fps)),
            loop=0,
        )
    return out
