"""``dg16m show``, ``dg16m inspect`` and ``dg16m grippers``: look at grasp files and grippers.

Heavy imports happen inside the handlers so that ``dg16m --help`` stays fast.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from dg16m_core.arguments import add_out_argument, add_seed_argument
from dg16m_core.cli import add_command
from dg16m_core.errors import Dg16mError


def register(subparsers: Any) -> None:
    """Add ``dg16m show``, ``inspect`` and ``grippers`` to the ``dg16m`` parser."""
    _register_show(subparsers)
    _register_inspect(subparsers)
    _register_grippers(subparsers)


def _register_show(subparsers: Any) -> None:
    show_grasps = add_command(
        subparsers,
        "show",
        "Render dual grasps of a DG16M file on its object to a PNG (passing vs failing).",
        "  dg16m show ../shared/data/real/dg16m_airplane.h5 \\\n"
        "      --mesh ../shared/data/real/dg16m_airplane.obj --out airplane.png --n 20\n",
        description=(
            "Render dual grasps of a DG16M file on its object to a PNG: passing pairs in the "
            "left panel, failing pairs in the right one."
        ),
    )
    show_grasps.add_argument("file", type=Path, help="DG16M release-schema HDF5 file")
    show_grasps.add_argument("--mesh", type=Path, required=True, help="the object's mesh file")
    add_out_argument(show_grasps, "PNG to write")
    show_grasps.add_argument(
        "--n",
        type=int,
        default=20,
        help="dual grasps drawn in all: N/2 passing (left) and N/2 failing (right); when one "
        "class has fewer, the other fills its slots (default: 20, i.e. 10 + 10)",
    )
    add_seed_argument(show_grasps, "which grasps are drawn (default: 0)")
    show_grasps.add_argument(
        "--gripper",
        default=None,
        help="gripper drawn: panda or robotiq_2f85 (default: the file's, else robotiq_2f85 as "
        "in the release)",
    )
    show_grasps.add_argument(
        "--view", default="25,-60", help="elevation,azimuth in degrees (default: 25,-60)"
    )
    show_grasps.set_defaults(handler=_show)


def _register_inspect(subparsers: Any) -> None:
    inspect = add_command(
        subparsers,
        "inspect",
        "Validate a grasp file (DG16M release schema or ACRONYM) and print a summary.",
        "  dg16m inspect ../shared/data/real/dg16m_airplane.h5\n"
        "  dg16m inspect ../shared/data/real/acronym_mug_10f6e090.h5\n"
        "  dg16m inspect runs/dg16m/grasps/table-0000000.h5 --dataset runs/dg16m\n",
    )
    inspect.add_argument("file", type=Path, help="HDF5 grasp file")
    inspect.add_argument(
        "--dataset",
        type=Path,
        default=None,
        help="also check that the file is the one this dataset folder ('dg16m dataset build') "
        "lists for its object (same sha256); a file inside a dataset folder is checked "
        "against it without this option",
    )
    inspect.set_defaults(handler=_inspect)


def _register_grippers(subparsers: Any) -> None:
    grippers = add_command(
        subparsers,
        "grippers",
        "List the gripper models and their dimensions (grasp frame convention in "
        "dataset_gen.grasps.gripper).",
        "  dg16m grippers\n",
    )
    grippers.set_defaults(handler=_grippers)


# --------------------------------------------------------------------------------------------
# Handlers
# --------------------------------------------------------------------------------------------


def _parse_view(text: str) -> tuple[float, float]:
    try:
        elev, azim = (float(v) for v in text.split(","))
    except ValueError:
        raise Dg16mError(
            f"--view: expected 'elevation,azimuth' in degrees, found {text!r}"
        ) from None
    return elev, azim


def _show(args: argparse.Namespace) -> int:
    from dataset_gen import io
    from dataset_gen.objects.grasp_object import load_object
    from dataset_gen.pipeline.render import render_dual_grasps, select_pairs

    if args.n <= 0:
        raise Dg16mError(f"--n: expected a positive number of grasps, found {args.n}")
    view = _parse_view(args.view)
    data = io.read_dg16m(args.file)
    # The grasp file's scale is authoritative: no size guess applies to it.
    obj = load_object(args.mesh, scale=data.object_scale, allow_any_size=True)
    gripper = args.gripper or data.metadata.get("gripper", "robotiq_2f85")
    out = render_dual_grasps(
        obj.mesh,
        data.grasps,
        data.passed,
        args.out,
        gripper=gripper,
        contact_points=data.contact_points,
        n=args.n,
        seed=args.seed,
        title=f"{args.file.name} on {args.mesh.name}: {data.n} dual grasps ({gripper})",
        view=view,
    )
    passing, failing = select_pairs(data.passed, args.n, args.seed)
    print(f"wrote {out}: {len(passing)} passing + {len(failing)} failing of {data.n} dual grasps")
    return 0


def _inspect(args: argparse.Namespace) -> int:
    from dataset_gen import io
    from dataset_gen.collection.build import check_member, dataset_folder_of

    kind = io.detect_format(args.file)
    if kind == "acronym":
        _print_acronym(args.file, io.read_acronym(args.file))
        return 0
    _print_dg16m(args.file, io.read_dg16m(args.file))
    folder = args.dataset if args.dataset is not None else dataset_folder_of(args.file)
    if folder is not None:
        entry = check_member(folder, args.file)
        print(
            f"  dataset       {folder}: object {args.file.stem} ({entry['split']} split, "
            f"{entry['origin'].get('source')}), sha256 as built"
        )
    return 0


def _print_acronym(path: Path, acr: Any) -> None:
    n = len(acr.transforms)
    rate = f" (flex success {acr.success.mean():.1%})" if n else ""
    print(f"{path}: ACRONYM single-arm grasps")
    print(f"  grasps        {n}{rate}")
    print(f"  object        {acr.object_file} (scale {acr.object_scale:g})")
    print(f"  gripper       {acr.gripper_type}")


def _print_dg16m(path: Path, data: Any) -> None:
    import h5py
    import numpy as np

    loss = data.loss_values
    print(f"{path}: DG16M release schema, valid")
    print(
        f"  dual grasps   {data.n} ({len(data.passing_indices)} passing, "
        f"{len(data.failed_indices)} failing)"
    )
    print(f"  object        {data.object_file} (scale {data.object_scale:g})")
    if len(data.passing_indices):
        print(f"  passing loss  max {loss[data.passing_indices].max():.3g} N")
    if len(data.failed_indices):
        print(f"  failing loss  min {loss[data.failed_indices].min():.3g} N")
    if data.n:
        width = np.linalg.norm(data.contact_points[:, 0] - data.contact_points[:, 1], axis=-1)
        print(f"  grasp widths  {width.min():.4f} .. {width.max():.4f} m")
    else:
        print("  grasp widths  - (the file stores no dual grasps)")
    if data.extras:
        print(f"  dg16m extras  {_names(data.extras)}")
    if data.metadata:
        print(f"  metadata      {_names(data.metadata)}")
    with h5py.File(path, "r") as handle:
        unknown = sorted(set(handle.keys()) - {"grasps", "object", "dg16m"})
    if unknown:
        print(f"  other groups  {_names(unknown)} (ignored)")


def _names(items: Sequence[str] | dict[str, Any]) -> str:
    return ", ".join(sorted(items))


def _grippers(args: argparse.Namespace) -> int:
    from dataset_gen.grasps.gripper import GRIPPERS

    for model in GRIPPERS.values():
        print(
            f"{model.name:14s} opening {model.max_opening * 1000:.0f} mm, "
            f"palm face y={model.palm_depth:.4f} m, contacts y={model.contact_depth:.4f} m, "
            f"fingertips y={model.finger_tip:.4f} m, force {model.max_force:.0f} N"
        )
        print(f"{'':14s} {model.description}")
    return 0
