"""Subcommands of ``dg16m`` provided by :mod:`dataset_gen`: objects, show, inspect, grippers.

Heavy imports happen inside the handlers so that ``dg16m --help`` stays fast.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from dataset_gen.errors import Dg16mError, MeshError


def _add(
    subparsers, name: str, help_text: str, examples: str, **kwargs: Any
) -> argparse.ArgumentParser:
    return subparsers.add_parser(
        name,
        help=help_text,
        description=help_text,
        epilog="examples:\n" + examples,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        **kwargs,
    )


def register(subparsers) -> None:
    """Add this package's subcommands to the ``dg16m`` parser."""
    objects = _add(
        subparsers,
        "objects",
        "Make, check and look at objects (the embedded procedural library or your meshes).",
        "  dg16m objects make --count 20 --seed 0 --out runs/objects\n"
        "  dg16m objects show runs/objects --out runs/objects.png\n"
        "  dg16m objects check my_meshes/*.obj --scale 0.001\n",
    )
    actions = objects.add_subparsers(dest="action", metavar="ACTION", required=True)

    make = _add(
        actions,
        "make",
        "Write procedural objects (meshes, convex parts, manifest) into a folder.",
        "  dg16m objects make --count 20 --seed 0 --out runs/objects\n"
        "  dg16m objects make --split benchmark --out runs/benchmark_objects   # all 300\n",
    )
    make.add_argument(
        "--count",
        type=int,
        default=None,
        help="number of objects (default: 20 for train, 300 for benchmark)",
    )
    make.add_argument(
        "--seed",
        type=int,
        default=0,
        help="first seed; object i uses family i %% F and seed SEED + i // F",
    )
    make.add_argument(
        "--split",
        choices=("train", "benchmark"),
        default="train",
        help="which split (default: train)",
    )
    make.add_argument(
        "--mass", type=float, default=6.0, help="object mass in kg (default: 6, the release value)"
    )
    make.add_argument(
        "--out", type=Path, required=True, help="output folder (reruns keep finished objects)"
    )
    make.set_defaults(handler=_objects_make)

    show = _add(
        actions,
        "show",
        "Render a contact sheet of the objects of a folder to a PNG.",
        "  dg16m objects show runs/objects --out runs/objects.png --limit 12\n",
    )
    show.add_argument("folder", type=Path, help="folder written by 'dg16m objects make'")
    show.add_argument("--out", type=Path, required=True, help="PNG to write")
    show.add_argument(
        "--limit", type=int, default=30, help="at most this many objects (default: 30)"
    )
    show.add_argument("--columns", type=int, default=5, help="objects per row (default: 5)")
    show.set_defaults(handler=_objects_show)

    check = _add(
        actions,
        "check",
        "Load mesh files as dg16m would and report size, mass properties and defects.",
        "  dg16m objects check ../shared/data/real/dg16m_airplane.obj\n"
        "  dg16m objects check mug.obj --scale 0.000268\n",
    )
    check.add_argument("meshes", nargs="+", type=Path, help="mesh files (OBJ, STL, PLY, OFF, GLB)")
    scale = check.add_mutually_exclusive_group()
    scale.add_argument(
        "--scale", type=float, default=None, help="factor applied to file coordinates"
    )
    scale.add_argument(
        "--target-extent", type=float, default=None, help="scale so the longest side is this many m"
    )
    check.add_argument("--mass", type=float, default=6.0, help="kg (default: 6)")
    check.set_defaults(handler=_objects_check)

    show_grasps = _add(
        subparsers,
        "show",
        "Render dual grasps of a DG16M file on its object to a PNG (passing vs failing).",
        "  dg16m show ../shared/data/real/dg16m_airplane.h5 \\\n"
        "      --mesh ../shared/data/real/dg16m_airplane.obj --out airplane.png --n 20\n",
    )
    show_grasps.add_argument("file", type=Path, help="DG16M release-schema HDF5 file")
    show_grasps.add_argument("--mesh", type=Path, required=True, help="the object's mesh file")
    show_grasps.add_argument("--out", type=Path, required=True, help="PNG to write")
    show_grasps.add_argument(
        "--n", type=int, default=20, help="number of dual grasps drawn (default: 20)"
    )
    show_grasps.add_argument(
        "--seed", type=int, default=0, help="which grasps are drawn (default: 0)"
    )
    show_grasps.add_argument(
        "--gripper",
        default=None,
        help="gripper drawn: panda or robotiq_2f85 (default: the file's, else robotiq_2f85 as in the release)",
    )
    show_grasps.add_argument(
        "--view", default="25,-60", help="elevation,azimuth in degrees (default: 25,-60)"
    )
    show_grasps.set_defaults(handler=_show)

    inspect = _add(
        subparsers,
        "inspect",
        "Validate a grasp file (DG16M release schema or ACRONYM) and print a summary.",
        "  dg16m inspect ../shared/data/real/dg16m_airplane.h5\n"
        "  dg16m inspect ../shared/data/real/acronym_mug_10f6e090.h5\n",
    )
    inspect.add_argument("file", type=Path, help="HDF5 grasp file")
    inspect.set_defaults(handler=_inspect)

    grippers = _add(
        subparsers,
        "grippers",
        "List the gripper models and their dimensions (grasp frame convention in dataset_gen.gripper).",
        "  dg16m grippers\n",
    )
    grippers.set_defaults(handler=_grippers)


# --------------------------------------------------------------------------------------------


def _objects_make(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from dataset_gen import procedural
    from dataset_gen.library import write_procedural_library

    count = args.count if args.count is not None else (300 if args.split == "benchmark" else 20)
    if count <= 0:
        raise MeshError(f"--count: expected a positive number of objects, found {count}")
    specs = procedural.object_specs(count, seed=args.seed, split=args.split)  # ProceduralError
    with tqdm(total=len(specs), unit="obj", desc="objects", disable=None) as bar:
        manifest = write_procedural_library(
            args.out, specs, mass=args.mass, on_object=lambda _: bar.update()
        )
    families = sorted({family for family, _ in specs})
    print(
        f"wrote {len(specs)} objects from {len(families)} families to {args.out} ({manifest.name})"
    )
    return 0


def _objects_show(args: argparse.Namespace) -> int:
    from dataset_gen.library import load_library
    from dataset_gen.render import render_objects

    objects = load_library(args.folder, limit=max(args.limit, 0))
    if not objects:
        raise MeshError(f"{args.folder}: expected at least one object in the manifest, found none")
    out = render_objects([(o.object_id, o.mesh) for o in objects], args.out, columns=args.columns)
    print(f"wrote {out} ({len(objects)} objects)")
    return 0


def _objects_check(args: argparse.Namespace) -> int:
    from dataset_gen.objects import load_object

    failures = 0
    for path in args.meshes:
        try:
            obj = load_object(
                path, scale=args.scale, target_extent=args.target_extent, mass=args.mass
            )
        except MeshError as exc:
            failures += 1
            print(f"FAIL {exc}")
            continue
        props = obj.mass_properties
        ext = " x ".join(f"{e:.3f}" for e in obj.extents)
        cleaned = ", ".join(f"{k}={v}" for k, v in vars(obj.cleaning).items() if v) or "nothing"
        print(
            f"ok   {path}: {len(obj.mesh.vertices)} vertices, {len(obj.mesh.faces)} faces, "
            f"{ext} m, scale {obj.scale:g}, watertight {obj.is_watertight}, "
            f"{props.model} mass model, centre of mass {props.center_of_mass.round(4).tolist()} m; "
            f"cleaned: {cleaned}"
        )
    if failures:
        print(f"{failures} of {len(args.meshes)} meshes failed", file=sys.stderr)
        return 1
    return 0


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
    from dataset_gen.objects import load_object
    from dataset_gen.render import render_dual_grasps

    if args.n <= 0:
        raise Dg16mError(f"--n: expected a positive number of grasps, found {args.n}")
    data = io.read_dg16m(args.file)
    obj = load_object(args.mesh, scale=data.object_scale)
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
        view=_parse_view(args.view),
    )
    print(f"wrote {out}")
    return 0


def _inspect(args: argparse.Namespace) -> int:
    import h5py
    import numpy as np

    from dataset_gen import io

    kind = io.detect_format(args.file)
    if kind == "acronym":
        acr = io.read_acronym(args.file)
        print(f"{args.file}: ACRONYM single-arm grasps")
        print(f"  grasps        {len(acr.transforms)} (flex success {acr.success.mean():.1%})")
        print(f"  object        {acr.object_file} (scale {acr.object_scale:g})")
        print(f"  gripper       {acr.gripper_type}")
        return 0
    data = io.read_dg16m(args.file)
    loss = data.loss_values
    print(f"{args.file}: DG16M release schema, valid")
    print(
        f"  dual grasps   {data.n} ({len(data.passing_indices)} passing, {len(data.failed_indices)} failing)"
    )
    print(f"  object        {data.object_file} (scale {data.object_scale:g})")
    if len(data.passing_indices):
        print(f"  passing loss  max {loss[data.passing_indices].max():.3g}")
    if len(data.failed_indices):
        print(f"  failing loss  min {loss[data.failed_indices].min():.3g}")
    width = np.linalg.norm(data.contact_points[:, 0] - data.contact_points[:, 1], axis=-1)
    print(f"  grasp widths  {width.min():.4f} .. {width.max():.4f} m")
    if data.extras or data.metadata:
        print(f"  dg16m extras  {sorted(data.extras)}; metadata keys {sorted(data.metadata)}")
    with h5py.File(args.file, "r") as handle:
        unknown = sorted(set(handle.keys()) - {"grasps", "object", "dg16m"})
    if unknown:
        print(f"  other groups  {unknown} (ignored)")
    return 0


def _grippers(args: argparse.Namespace) -> int:
    from dataset_gen.gripper import GRIPPERS

    for model in GRIPPERS.values():
        print(
            f"{model.name:14s} opening {model.max_opening * 1000:.0f} mm, palm face y={model.palm_depth:.4f} m, "
            f"contacts y={model.contact_depth:.4f} m, fingertips y={model.finger_tip:.4f} m, "
            f"force {model.max_force:.0f} N"
        )
        print(f"{'':14s} {model.description}")
    return 0
