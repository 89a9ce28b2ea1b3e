"""``dg16m objects``: make, show, check, decompose, import and repair objects.

Heavy imports happen inside the handlers so that ``dg16m --help`` stays fast; ``objects
decompose`` and ``objects import-sweethome3d``, whose defaults live in modules that import
trimesh, add their arguments when they are used (``add_command(..., arguments=...)``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from dg16m_core import arguments
from dg16m_core.checks import check_integer, check_number
from dg16m_core.cli import add_command
from dg16m_core.errors import Dg16mError, MeshError
from dg16m_core.parameters import PAPER

DEFAULT_TRAIN_COUNT = 20
"""Objects made by ``dg16m objects make`` on the train split when ``--count`` is not given."""


def register(subparsers: Any) -> None:
    """Add ``dg16m objects`` and its actions to the ``dg16m`` parser."""
    objects = add_command(
        subparsers,
        "objects",
        "Make, check and look at objects (the embedded procedural library or your meshes).",
        "  dg16m objects make --count 20 --seed 0 --out runs/objects\n"
        "  dg16m objects show runs/objects --out runs/objects.png\n"
        "  dg16m objects check my_meshes/*.obj --scale 0.001\n"
        "  dg16m objects repair my_meshes --out runs/my_meshes_repaired\n",
    )
    actions = objects.add_subparsers(dest="action", metavar="ACTION", required=True)
    _register_objects_make(actions)
    _register_objects_show(actions)
    _register_objects_check(actions)
    _register_objects_decompose(actions)
    _register_objects_import_sweethome3d(actions)
    _register_objects_repair(actions)


def _register_objects_make(actions: Any) -> None:
    make = add_command(
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
        help=f"number of objects (default: {DEFAULT_TRAIN_COUNT} for train, all 300 for benchmark)",
    )
    arguments.add_seed_argument(
        make, "first seed; object i uses family i %% F and seed SEED + i // F"
    )
    make.add_argument(
        "--split",
        choices=("train", "benchmark"),
        default="train",
        help="which split (default: train)",
    )
    make.add_argument(
        "--mass",
        type=float,
        default=PAPER.mass,
        help=f"object mass in kg (default: {PAPER.mass:g}, the release value)",
    )
    arguments.add_out_argument(make, "output folder (reruns keep finished objects)")
    make.set_defaults(handler=_objects_make)


def _register_objects_show(actions: Any) -> None:
    show = add_command(
        actions,
        "show",
        "Render a contact sheet of the objects of a folder to a PNG.",
        "  dg16m objects show runs/objects --out runs/objects.png --limit 12\n",
    )
    show.add_argument("folder", type=Path, help="folder written by 'dg16m objects make'")
    arguments.add_out_argument(show, "PNG to write")
    arguments.add_limit_argument(show, "at most this many objects, >= 1 (default: 30)", default=30)
    show.add_argument("--columns", type=int, default=5, help="objects per row (default: 5)")
    show.set_defaults(handler=_objects_show)


def _register_objects_check(actions: Any) -> None:
    check = add_command(
        actions,
        "check",
        "Load mesh files as dg16m would and report size, mass properties and defects.",
        "  dg16m objects check ../shared/data/real/dg16m_airplane.obj\n"
        "  dg16m objects check raw_meshes/            # every mesh file in the folder\n"
        "  dg16m objects check box_in_millimetres.obj --units mm   # or --scale 0.001\n"
        "  dg16m objects check ../shared/data/real/acronym_mug_10f6e090.obj \\\n"
        "      --scale 0.000268 --allow-any-size   # a single-arm object\n",
        description=(
            "Load mesh files as dg16m would and report size, mass properties and defects, and "
            "whether each is a watertight solid or a shell (open, or in pieces that do not close "
            "a volume) with what 'benchmark build' will do with it: a shell is simulated with "
            "its mass spread over the surface and voxel-remeshed by CoACD; 'dg16m objects "
            "repair' makes it a solid first. Folders are expanded to the mesh files in them (not "
            "recursive). A longest side outside the plausible range of a dual-arm object "
            "(0.05-5 m) is an error that suggests a --scale (files in millimetres need --scale "
            "0.001) unless --allow-any-size is given; without --units or --scale the file is "
            "read as metres and checked against the units rule of 'objects repair' (the same "
            "guess, a warning for a table-sized object of a unitless OBJ/STL/PLY/OFF file). Each "
            "mesh's up axis is reported as 'objects repair' would take it (--up): 'benchmark "
            "build' reads every file z up, so repair a y-up file first. Exit status: 0 when every "
            "mesh loads, 1 otherwise."
        ),
    )
    check.add_argument(
        "meshes",
        nargs="+",
        type=Path,
        help="mesh files (OBJ, STL, PLY, OFF, GLB, GLTF), or folders of them",
    )
    scale = check.add_mutually_exclusive_group()
    scale.add_argument(
        "--scale", type=float, default=None, help="factor applied to file coordinates"
    )
    scale.add_argument(
        "--units",
        choices=("m", "cm", "mm", "inch"),
        default=None,
        help="the files' unit (as 'objects repair --units'; default: read as metres and "
        "checked against the units guess)",
    )
    scale.add_argument(
        "--target-extent", type=float, default=None, help="scale so the longest side is this many m"
    )
    check.add_argument(
        "--allow-any-size",
        action="store_true",
        help="accept a longest side outside 0.05-5 m (still within 1 mm - 100 m)",
    )
    check.add_argument(
        "--mass", type=float, default=PAPER.mass, help=f"kg (default: {PAPER.mass:g})"
    )
    _add_up_argument(check)
    check.set_defaults(handler=_objects_check)


def _register_objects_decompose(actions: Any) -> None:
    add_command(
        actions,
        "decompose",
        "Decompose meshes into convex hulls (CoACD, cached) and report how far the hulls stick "
        "out of the mesh.",
        "  dg16m objects decompose tests/data/meshes/couch.obj\n"
        "  dg16m objects decompose my_meshes/*.obj --scale 0.001 --out runs/hulls\n"
        "  dg16m objects decompose couch.obj --threshold 0.02 --preprocess on --no-cache \\\n"
        "      --json couch_report.json\n",
        description=(
            "Load mesh files as dg16m does (object frame: centred, at --scale), decompose each "
            "into convex hulls with CoACD the way the simulator does (read from or written to "
            "the cache) and report per mesh: faces, watertightness, whether CoACD's voxel "
            "repair ran (auto: only for meshes that are not a closed volume), hulls, the "
            "one-sided hull-to-mesh deviation (max / p95 / mean over points sampled on the "
            "hulls, in mm; an open hand closer than that to the mesh can start inside a hull), "
            "the extra volume of the hulls in %, the time and the cache file. Every mesh is "
            "loaded before any decomposition, and files are written only when all succeed. "
            "Exit status: 0 on success, 2 for bad input (nothing written)."
        ),
        arguments=_objects_decompose_arguments,
    )


def _objects_decompose_arguments(decompose: argparse.ArgumentParser) -> None:
    from dataset_gen.objects.decomposition import DEFAULT_THRESHOLD  # trimesh, SciPy: on use only

    decompose.add_argument(
        "meshes", nargs="+", type=Path, help="mesh files (OBJ, STL, PLY, OFF, GLB)"
    )
    decompose.add_argument(
        "--scale",
        type=float,
        default=None,
        metavar="S",
        help="factor applied to file coordinates",
    )
    decompose.add_argument(
        "--allow-any-size",
        action="store_true",
        help="accept a longest side outside 0.05-5 m (still within 1 mm - 100 m)",
    )
    decompose.add_argument(
        "--threshold",
        type=float,
        default=DEFAULT_THRESHOLD,
        metavar="T",
        help=f"CoACD concavity threshold in (0, 1] (default: {DEFAULT_THRESHOLD:g})",
    )
    decompose.add_argument(
        "--preprocess",
        choices=("auto", "on", "off"),
        default="auto",
        help="CoACD's voxel repair: auto runs it only for meshes that are not a closed volume "
        "(default: auto)",
    )
    decompose.add_argument(
        "--out",
        type=Path,
        default=None,
        metavar="DIR",
        help="folder for NAME.obj (each hull its own object) and NAME.json (the report)",
    )
    decompose.add_argument(
        "--cache-dir",
        type=Path,
        default=None,
        metavar="DIR",
        help="CoACD cache folder (default: $DG16M_CACHE_DIR/coacd or ~/.cache/dg16m/coacd)",
    )
    decompose.add_argument(
        "--no-cache", action="store_true", help="always run CoACD; read and write no cache"
    )
    decompose.add_argument(
        "--json", type=Path, default=None, metavar="FILE", help="write all reports to FILE"
    )
    decompose.add_argument(
        "--samples",
        type=int,
        default=20000,
        metavar="N",
        help="points sampled on the hulls (and Monte-Carlo points for the volume), >= 100 "
        "(default: 20000)",
    )
    decompose.set_defaults(handler=_objects_decompose)


def _register_objects_import_sweethome3d(actions: Any) -> None:
    add_command(
        actions,
        "import-sweethome3d",
        "Import real furniture from Debian's sweethome3d-furniture libraries as a mesh folder.",
        "  apt-get install -y sweethome3d-furniture\n"
        "  dg16m objects import-sweethome3d --list                 # the catalogue and the filter\n"
        "  dg16m objects import-sweethome3d --out runs/real --workers 2\n"
        "  dg16m objects import-sweethome3d --out runs/chairs --category Office --limit 5\n"
        "  dg16m benchmark build --meshes runs/real --out runs/real_bench\n",
        description=_import_sweethome3d_description,
        arguments=_objects_import_sweethome3d_arguments,
    )


def _import_sweethome3d_description() -> str:
    from dataset_gen.real.sweethome3d import MAX_ASPECT, SIZE_RANGE_M  # trimesh: on use only

    return (
        "Read the Sweet Home 3D furniture libraries (*.sh3f), keep the models that are "
        "dual-arm objects (no people, doors, windows, stairs, vehicles, plants, "
        f"textiles; longest / shortest catalogue side <= {MAX_ASPECT:g}), scale each to its "
        f"catalogue size, then to a longest side in {SIZE_RANGE_M[0]:g}-{SIZE_RANGE_M[1]:g} m "
        "(kept when the catalogue's is in range, else drawn uniformly, seeded), rebuild it "
        "as one watertight volume (filled-voxel remesh, Taubin smoothing, stepwise quadric "
        "decimation) and write OUT/<id>.obj in metres, OUT/manifest.json (source, creator, "
        "licence, catalogue size, scale, repair, deviation from the source, sha256) and "
        "OUT/ATTRIBUTION.md. Resumable. A model that cannot be repaired is listed with its "
        "reason and skipped. Exit status: 0 when every model imported, 1 when some failed."
    )


def _objects_import_sweethome3d_arguments(command: argparse.ArgumentParser) -> None:
    from dataset_gen.real.sweethome3d import DEFAULT_ROOT

    arguments.add_out_argument(command, "output folder (required unless --list)", required=False)
    command.add_argument(
        "--root",
        type=Path,
        default=DEFAULT_ROOT,
        help=f"folder of *.sh3f (default: {DEFAULT_ROOT})",
    )
    command.add_argument(
        "--list", action="store_true", help="print the catalogue with the filter's verdicts"
    )
    command.add_argument("--ids", default=None, help="comma-separated object ids to import")
    command.add_argument(
        "--category",
        action="append",
        default=None,
        help="only this catalogue category (repeatable)",
    )
    arguments.add_limit_argument(command, "import the first N selected models")
    arguments.add_seed_argument(command, "seed of the drawn sizes (default: 0)")
    _add_remesh_arguments(command, "object")
    command.set_defaults(handler=_objects_import_sweethome3d)


def _add_remesh_arguments(command: argparse.ArgumentParser, item: str) -> None:
    """The remesh options of ``import-sweethome3d`` and ``repair`` (``item``: what one output
    file holds, for the help), then ``--workers`` and ``--no-progress``."""
    from dataset_gen.real.repair import RepairParameters  # trimesh: on use only

    defaults = RepairParameters()
    command.add_argument(
        "--target-faces",
        type=int,
        default=defaults.target_faces,
        help=f"most faces per {item} (default: {defaults.target_faces})",
    )
    command.add_argument(
        "--pitch-fraction",
        type=float,
        default=defaults.pitch_fraction,
        help=f"voxel size / longest side of the remesh (default: {defaults.pitch_fraction:g})",
    )
    arguments.add_parallel_arguments(command, "processes (default: 1)", ray=False)
    arguments.add_progress_argument(command)


def _objects_import_sweethome3d(args: argparse.Namespace) -> int:
    import json
    from collections import Counter

    from dataset_gen.real.repair import RepairParameters
    from dataset_gen.real.sweethome3d import (
        exclusion_reason,
        import_library,
        import_summary,
        read_catalogs,
        select_entries,
    )

    entries = read_catalogs(args.root)
    if args.list:
        reasons: Counter[str] = Counter()
        for entry in entries:
            reason = exclusion_reason(entry)
            reasons[(reason or "kept").split(" (")[0]] += 1
            print(
                f"{'keep' if reason is None else 'drop'} {entry.object_id:44s} {entry.category:15s} "
                f"{entry.width:7.1f} x {entry.depth:7.1f} x {entry.height:7.1f} cm  {entry.name}"
                + ("" if reason is None else f"  [{reason}]")
            )
        print(f"{len(entries)} models: " + ", ".join(f"{k} {v}" for k, v in reasons.most_common()))
        return 0
    if args.out is None:
        raise MeshError("--out: expected an output folder (or --list), found none")
    if args.limit is not None:
        check_integer("--limit", args.limit, minimum=1, error=MeshError)
    ids = [i.strip() for i in args.ids.split(",") if i.strip()] if args.ids else None
    chosen = select_entries(entries, ids=ids, categories=args.category, limit=args.limit)
    repair = RepairParameters(target_faces=args.target_faces, pitch_fraction=args.pitch_fraction)
    manifest = import_library(
        args.out,
        chosen,
        root=args.root,
        seed=args.seed,
        repair=repair,
        workers=args.workers,
        progress=not args.no_progress,
    )
    summary = import_summary(
        {"entries": {e.object_id: manifest["entries"][e.object_id] for e in chosen}}
    )
    print(json.dumps({k: v for k, v in summary.items() if k != "failures"}))
    for object_id, error in summary["failures"].items():
        print(f"FAIL {object_id}: {error}")
    print(f"{summary['ok']} of {len(chosen)} models in {args.out} (manifest.json, ATTRIBUTION.md)")
    return 1 if summary["failed"] else 0


def _register_objects_repair(actions: Any) -> None:
    add_command(
        actions,
        "repair",
        "Repair your mesh files (any units, holes, pieces) into one watertight body each, in "
        "metres, for 'benchmark build'.",
        "  dg16m objects repair my_meshes --out runs/my_meshes_repaired\n"
        "  dg16m objects repair cad_parts --out runs/parts --units mm --workers 2\n"
        "  dg16m objects repair my_meshes/chair.obj --out runs/my_meshes_repaired --units cm\n"
        "  dg16m objects repair scans --out runs/scans --target-extent 0.8\n"
        "  dg16m benchmark build --meshes runs/my_meshes_repaired --out runs/mine\n",
        description=_objects_repair_description,
        arguments=_objects_repair_arguments,
    )


def _objects_repair_description() -> str:
    from dataset_gen.objects.grasp_object import DUAL_ARM_MAX_EXTENT_M, DUAL_ARM_MIN_EXTENT_M
    from dataset_gen.real.own_meshes import INPUT_SUFFIXES, TYPICAL_EXTENT_M  # trimesh: on use

    low, high = TYPICAL_EXTENT_M
    return (
        "Read mesh files (a folder of them, not recursive, or single files: "
        f"{', '.join(s.lstrip('.').upper() for s in INPUT_SUFFIXES)}; COLLADA needs pycollada), "
        "bring each to metres, turn it z up (--up) and rebuild it as the Sweet Home 3D importer "
        "does: one watertight "
        "body (filled-voxel remesh, largest piece, Taubin smoothing, stepwise quadric "
        "decimation), its deviation from the source measured both ways. A mesh that is already "
        "one watertight body within the face budget is only scaled. Writes OUT/<stem>.obj and "
        "OUT/manifest.json (per mesh: the source file and its sha256, the up axis, the units "
        "decision, the "
        "operations applied, the deviation, the OBJ's sha256), so that 'dg16m benchmark build "
        "--meshes OUT' reads the folder. Units per mesh: --units, or --target-extent (the "
        "longest side in m), or a guess among metres, centimetres and millimetres that is "
        f"taken only when exactly one of them gives a longest side of {low:g}-{high:g} m, "
        "printed for every mesh; any other size is refused with what each unit would make of "
        f"it (a 9-unit chair: 9 m or 9 cm?). Given units must give {DUAL_ARM_MIN_EXTENT_M:g}-"
        f"{DUAL_ARM_MAX_EXTENT_M:g} m; a guess that makes an OBJ/STL/PLY/OFF file (no units) "
        "longer than 1.5 m is printed with a warning. A mesh that fails (unreadable, empty, NaN "
        "coordinates, "
        "units refused, repair failed) is reported with its reason and the others go on. "
        "Reruns keep the meshes already repaired from the same source with the same options "
        "and redo the rest, so a failed mesh can be rerun alone with its own --units. Exit "
        "status: 0 when every mesh is repaired, 1 when some failed, 2 for bad input."
    )


def _objects_repair_arguments(command: argparse.ArgumentParser) -> None:
    from dataset_gen.real.own_meshes import UNIT_FACTORS

    command.add_argument(
        "inputs", nargs="+", type=Path, metavar="IN", help="a folder of mesh files, or mesh files"
    )
    arguments.add_out_argument(command, "output folder (a rerun adds to it)")
    units = command.add_mutually_exclusive_group()
    units.add_argument(
        "--units",
        choices=tuple(UNIT_FACTORS),
        default=None,
        help="the files' unit (default: guessed per mesh, refused when unclear)",
    )
    units.add_argument(
        "--target-extent",
        type=float,
        default=None,
        metavar="METRES",
        help="scale every mesh to this longest side (m)",
    )
    _add_up_argument(command)
    _add_remesh_arguments(command, "mesh")
    command.set_defaults(handler=_objects_repair)


def _add_up_argument(command: argparse.ArgumentParser) -> None:
    command.add_argument(
        "--up",
        choices=("auto", "y", "z"),
        default="auto",
        help="the files' up axis; every mesh is written z up, a y-up one turned +90 deg about x "
        "(default auto: z for meshes dg16m wrote, else the format's convention: OBJ and "
        "GLB/glTF y up, STL, PLY, OFF and 3MF z up, COLLADA its <up_axis>)",
    )


def _objects_repair(args: argparse.Namespace) -> int:
    from dataset_gen.real.own_meshes import entry_line, repair_meshes, repair_summary
    from dataset_gen.real.repair import RepairParameters
    from dg16m_core.progress import progress_write

    if args.target_extent is not None:
        check_number("--target-extent", args.target_extent, error=MeshError)
    try:
        params = RepairParameters(
            target_faces=args.target_faces, pitch_fraction=args.pitch_fraction
        )
    except MeshError as exc:
        raise MeshError(f"--{str(exc).replace('_', '-')}") from None

    def report(object_id: str, entry: Any, kept: bool) -> None:
        progress_write(entry_line(object_id, entry, kept))

    run = repair_meshes(
        args.inputs,
        args.out,
        units=args.units,
        target_extent=args.target_extent,
        params=params,
        up=args.up,
        workers=args.workers,
        progress=not args.no_progress,
        on_entry=report,
    )
    entries = {i: run.manifest["entries"][i] for i in run.ids}
    summary = repair_summary(entries)
    if run.skipped:
        kinds = sorted({p.suffix.lower() or p.name for p in run.skipped})
        print(f"skipped {len(run.skipped)} files that are not meshes ({', '.join(kinds[:8])})")
    parts = [f"{len(run.repaired)} repaired"]
    if run.kept:
        parts.append(f"{len(run.kept)} kept from an earlier run")
    parts.append(f"{len(run.failed)} failed")
    print(f"{len(entries)} meshes: {', '.join(parts)}; {args.out}/manifest.json")
    if summary["ok"]:
        p10, p50, p90 = summary["seconds_p10_p50_p90"]
        d10, d50, d90 = summary["to_source_p95_mm_p10_p50_p90"]
        print(
            f"seconds per mesh p10/p50/p90 {p10:.1f} / {p50:.1f} / {p90:.1f}; deviation "
            f"(repaired to source, p95) {d10:.1f} / {d50:.1f} / {d90:.1f} mm"
        )
    if run.failed:
        units = [i for i in run.failed if _failure_kind(entries[i]) == "units"]
        advice = (  # only a units failure is fixed by --units (not an empty or broken file)
            f"; rerun {', '.join(units)} alone with its own --units or --target-extent"
            if units
            else ""
        )
        print(
            f"{len(run.failed)} failed: {', '.join(run.failed)} (reasons above and in the "
            f"manifest{advice})",
            file=sys.stderr,
        )
        return 1
    print(f"next: dg16m benchmark build --meshes {args.out} --out OUT")
    return 0


def _failure_kind(entry: Any) -> str | None:
    """``error_kind`` of a failed entry, or of the failure kept beside an earlier mesh."""
    return entry.get("error_kind") or entry.get("last_failure", {}).get("error_kind")


def _objects_make(args: argparse.Namespace) -> int:
    from dataset_gen.sources import procedural
    from dataset_gen.sources.library import write_procedural_library
    from dg16m_core.progress import progress_bar

    default_count = procedural.BENCHMARK_SIZE if args.split == "benchmark" else DEFAULT_TRAIN_COUNT
    count = args.count if args.count is not None else default_count
    if count <= 0:
        raise MeshError(f"--count: expected a positive number of objects, found {count}")
    mass = check_number("--mass", args.mass, error=MeshError)
    specs = procedural.object_specs(count, seed=args.seed, split=args.split)  # ProceduralError
    with progress_bar(total=len(specs), unit="obj", desc="objects") as bar:
        manifest = write_procedural_library(
            args.out, specs, mass=mass, on_object=lambda _: bar.update()
        )
    families = sorted({family for family, _ in specs})
    print(
        f"wrote {len(specs)} objects from {len(families)} families to {args.out} ({manifest.name})"
    )
    return 0


def _objects_show(args: argparse.Namespace) -> int:
    from dataset_gen.pipeline.render import render_objects
    from dataset_gen.sources.library import load_library

    limit = check_integer("--limit", args.limit, minimum=1, error=Dg16mError)
    columns = check_integer("--columns", args.columns, minimum=1, error=Dg16mError)
    objects = load_library(args.folder, limit=limit)
    if not objects:
        raise MeshError(
            f"{args.folder}: expected at least one ok object in the manifest, found none"
        )
    out = render_objects([(o.object_id, o.mesh) for o in objects], args.out, columns=columns)
    print(f"wrote {out} ({len(objects)} objects)")
    return 0


def _objects_check(args: argparse.Namespace) -> int:
    from dataset_gen.objects.grasp_object import MESH_SUFFIXES, UNIT_FACTORS, load_object
    from dataset_gen.real.own_meshes import find_meshes

    mass = check_number("--mass", args.mass, error=MeshError)
    # folders expand to their mesh files; nothing to check is bad input (exit 2)
    meshes, skipped = find_meshes(args.meshes, MESH_SUFFIXES, one_per_stem=False)
    folders = [str(p) for p in args.meshes if Path(p).is_dir()]
    if folders:
        others = f" (skipped {len(skipped)} other files)" if skipped else ""
        print(f"found {len(meshes)} mesh files in {', '.join(folders)}{others}")
    scale = UNIT_FACTORS[args.units] if args.units else args.scale
    failures = 0
    kinds = {"solid": 0, "shell": 0}
    y_up = []
    for path in meshes:
        try:
            obj = load_object(
                path,
                scale=scale,
                target_extent=args.target_extent,
                mass=mass,
                allow_any_size=args.allow_any_size,
            )
        except MeshError as exc:  # an empty or unreadable file: its own error, no units advice
            failures += 1
            print(f"FAIL {exc}")
            continue
        kind, verdict = solid_or_shell(obj.mesh)
        kinds[kind] += 1
        print(f"ok   {path}: {describe_object(obj)}")
        print(f"     {verdict}")
        lines, axis = _units_and_up(path, obj, args)
        for line in lines:
            print(f"     {line}")
        if axis == "y":
            y_up.append(path.stem)
    counts = [f"{kinds['solid']} solid", f"{kinds['shell']} shell", f"{failures} failed"]
    print(f"{len(meshes)} meshes: {', '.join(counts)}")
    if kinds["shell"]:
        print(
            "to make the shells watertight solids: dg16m objects repair FOLDER_OR_FILES "
            "--out REPAIRED (then build from REPAIRED)"
        )
    if y_up:
        print(
            f"{len(y_up)} y up ({', '.join(y_up[:5])}{', ...' if len(y_up) > 5 else ''}): "
            "'benchmark build' would simulate them on their side; 'dg16m objects repair' "
            "writes them z up"
        )
    if failures:
        print(f"{failures} of {len(meshes)} meshes failed", file=sys.stderr)
        return 1
    return 0


def _units_and_up(path: Path, obj: Any, args: argparse.Namespace) -> tuple[list[str], str]:
    """What ``objects check`` assumed of a loaded mesh's units (the one units rule of
    ``objects repair``) and up axis (:func:`~dataset_gen.real.orientation.up_axis`), as lines for
    people, and the up axis."""
    from dataset_gen.objects.grasp_object import (
        UNIT_NAMES,
        UNITS_FLAG,
        guess_units,
        large_guess_warning,
        unit_readings,
    )
    from dataset_gen.real.orientation import up_axis, written_by_dg16m

    lines = []
    origin = written_by_dg16m(path)
    if args.units:
        lines.append(f"units given: {UNIT_NAMES[args.units]}")
    elif origin is not None and args.scale is None and args.target_extent is None:
        lines.append(f"units: metres ({origin})")
    elif args.scale is None and args.target_extent is None:
        longest = float(max(obj.extents))  # file units: read as metres
        unit = guess_units(longest)
        if unit == "m":
            lines.append("units: metres (guessed: the only unit giving a typical size)")
            warning = large_guess_warning("m", obj.extents, path.suffix)
            if warning:
                lines.append(f"WARNING {warning}")
        elif unit is None:
            lines.append(
                f"units: read as metres, but 'objects repair' would not guess them "
                f"({unit_readings(longest)}); pass {UNITS_FLAG} if they are not metres"
            )
        else:  # only with --allow-any-size: out of the dual-arm range in metres
            lines.append(
                f"units: read as metres, but the units guess is {UNIT_NAMES[unit]}; pass "
                f"--units {unit} if so"
            )
    axis = up_axis(path, args.up)
    height = float(obj.extents[1 if axis.axis == "y" else 2])
    stands = (
        "'benchmark build' reads files z up, so it would lie on its side: 'dg16m objects "
        "repair' turns it z up"
        if axis.axis == "y"
        else "stands as 'benchmark build' reads it"
    )
    other = "z" if axis.axis == "y" else "y"
    hint = f"; pass --up {other} if wrong" if axis.how == "assumed" else ""
    lines.append(
        f"up axis {axis.axis} ({axis.how}: {axis.why}{hint}): {height:.3f} m tall along "
        f"{axis.axis}; {stands}"
    )
    return lines, axis.axis


def solid_or_shell(mesh: Any) -> tuple[str, str]:
    """``("solid" | "shell", what dg16m's build does with it)`` for a loaded mesh (for people).

    A solid is what the mass model calls one (:func:`dataset_gen.objects.grasp_object.mass_properties`):
    watertight, consistently wound, positive volume. Anything else is a shell.
    """
    import trimesh

    bodies = int(mesh.body_count)
    pieces = f"{bodies} separate pieces" if bodies > 1 else "one piece"
    if mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0:
        what = (
            f"watertight, {bodies} separate closed bodies that move as one rigid object; "
            "objects repair would keep only the largest"
            if bodies > 1
            else "watertight, one closed volume"
        )
        return "solid", (
            f"solid ({what}): benchmark build and generate use it as it is (mass from its "
            "volume; CoACD decomposes it without its voxel repair)"
        )
    if not mesh.is_watertight:
        open_edges = len(trimesh.grouping.group_rows(mesh.edges_sorted, require_count=1))
        why = f"not watertight: {open_edges} open edges, {pieces}"
    elif not mesh.is_winding_consistent:
        why = f"watertight but its faces are wound inconsistently, {pieces}"
    else:
        why = f"watertight but inside out (volume {mesh.volume:.3g} m^3), {pieces}"
    return "shell", (
        f"shell, not a solid ({why}): benchmark build treats it as a shell (mass spread over "
        "its surface; CoACD voxel-remeshes it before decomposing, so its hulls stand off the "
        "surface); run 'dg16m objects repair' first to make it one watertight solid"
    )


def _objects_decompose(args: argparse.Namespace) -> int:
    from dataset_gen.objects import decomposition as dec
    from dataset_gen.objects.grasp_object import load_object
    from dg16m_core.atomic import write_json_atomic, write_text_atomic
    from dg16m_core.stopping import sigterm_interrupts

    try:
        params = dec.DecompositionParameters(threshold=args.threshold, preprocess=args.preprocess)
    except MeshError as exc:
        raise MeshError(f"--{exc}") from None
    samples = check_integer("--samples", args.samples, minimum=100, error=Dg16mError)
    if args.scale is not None:
        check_number("--scale", args.scale, error=MeshError)
    if args.out is not None and args.out.exists() and not args.out.is_dir():
        raise Dg16mError(f"--out: expected a folder, found the file {args.out}")
    if args.json is not None and args.json.is_dir():
        raise Dg16mError(f"--json: expected a file name, found the folder {args.json}")
    stems: dict[str, Path] = {}
    for path in args.meshes:
        if args.out is not None and path.stem in stems:
            raise Dg16mError(
                f"--out: expected mesh files with distinct names, found {stems[path.stem]} and "
                f"{path} (both would write {path.stem}.obj)"
            )
        stems[path.stem] = path
    # Load everything first: a broken file fails before any slow decomposition or any write.
    objects = [
        load_object(path, scale=args.scale, allow_any_size=args.allow_any_size)
        for path in args.meshes
    ]
    entries = []
    with sigterm_interrupts():  # SIGTERM stops it as Ctrl-C does (exit 130)
        for path, obj in zip(args.meshes, objects, strict=True):
            print(
                f"decomposing {path} (CoACD, threshold {params.threshold:g}) ...",
                file=sys.stderr,
                flush=True,
            )
            stats: dict[str, Any] = {}
            parts = dec.convex_decomposition(  # CoACD in a child process that Ctrl-C stops
                obj.mesh,
                params=params,
                cache_dir=args.cache_dir,
                use_cache=not args.no_cache,
                name=str(path),
                stats=stats,
                stoppable=True,
            )
            report = dec.decomposition_report(
                obj.mesh, parts, samples=samples, stats=stats, name=str(path)
            )
            print(report.format(), flush=True)
            entries.append((path, obj, parts, report))
    payloads = [
        {
            "mesh": str(path),
            "scale": obj.scale,
            "parameters": params.to_dict(),
            "coacd_version": dec.coacd_version(),
            "report": report.to_dict(),
        }
        for path, obj, _, report in entries
    ]
    if args.out is not None:
        for (path, _, parts, _), payload in zip(entries, payloads, strict=True):
            write_text_atomic(args.out / f"{path.stem}.obj", dec.parts_to_obj(parts))
            write_json_atomic(args.out / f"{path.stem}.json", payload)
        print(f"wrote {2 * len(entries)} files to {args.out}")
    if args.json is not None:
        write_json_atomic(args.json, {"format": "dg16m-decomposition", "meshes": payloads})
        print(f"wrote {args.json}")
    return 0


def describe_object(obj: Any) -> str:
    """One line about a loaded :class:`~dataset_gen.objects.grasp_object.GraspObject`, for people."""
    props = obj.mass_properties
    size = " x ".join(f"{e:.3f}" for e in obj.extents)
    com = ", ".join(f"{0.0 if abs(c) < 5e-5 else c:.4f}" for c in props.center_of_mass)
    return (
        f"{len(obj.mesh.vertices)} vertices, {len(obj.mesh.faces)} faces; {size} m "
        f"(scale {obj.scale:g}); {'watertight' if obj.is_watertight else 'NOT watertight'}, "
        f"{props.model} mass model, {props.mass:g} kg, centre of mass ({com}) m; "
        f"cleaning: {obj.cleaning.words() or 'nothing to clean'}"
    )
