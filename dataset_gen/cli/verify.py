"""``dg16m verify``: recompute the force-closure verdicts of a DG16M file and compare.

The logic lives in :mod:`dataset_gen.pipeline.verify`; this module only parses arguments and prints.
Heavy imports happen inside the handler so that ``dg16m --help`` stays fast.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from dg16m_core.arguments import add_limit_argument
from dg16m_core.cli import add_command

EXAMPLES = (
    "  # a DG16M release file (the release used the outward normal as the cone axis)\n"
    "  dg16m verify ../shared/data/real/dg16m_airplane.h5 \\\n"
    "      --mesh ../shared/data/real/dg16m_airplane.obj --convention release\n"
    "  # a file of 'dg16m generate --procedural 20 --out runs/dataset' (physical convention),\n"
    "  # full report as JSON, exit 1 on disagreements that ambiguous normals do not explain\n"
    "  dg16m verify runs/dataset/grasps/table-0000000.h5 \\\n"
    "      --mesh runs/dataset/meshes/table-0000000.obj --json runs/verify_table.json --strict\n"
)

DESCRIPTION = (
    "Recompute the force-closure verdict and loss of every stored dual grasp of a DG16M "
    "release-schema file and report how many agree with the stored ones, listing the pairs "
    "that disagree and why. The mesh is loaded as the released code did (raw trimesh load, "
    "scaled by object/scale, centred at the centroid); normals are the faces' under the "
    "contacts (or dg16m/contact_normals when the file stores them). Contacts on edges or on "
    "two-sided surfaces lie on several faces: the face choices that reproduce the stored "
    "results are searched per pair and then as one face per contact point over the file. "
    "Exit status: 0, or 1 with --strict when a disagreement is not explained by ambiguous "
    "normals, a contact is off the mesh, or the face choices point to the other convention; "
    "2 for unusable input."
)


def register(subparsers: Any) -> None:
    """Add ``dg16m verify`` to the ``dg16m`` parser."""
    parser = add_command(
        subparsers,
        "verify",
        "Recompute the force-closure verdicts of a DG16M file and compare with the stored ones.",
        EXAMPLES,
        description=DESCRIPTION,
    )
    parser.add_argument("file", type=Path, metavar="FILE", help="DG16M release-schema HDF5 file")
    parser.add_argument(
        "--mesh", type=Path, required=True, help="the object's mesh file (as named by object/file)"
    )
    parser.add_argument(
        "--convention",
        choices=("physical", "release"),
        default="physical",
        help="friction-cone convention: physical (fingers push; dg16m's files, the default) or "
        "release (outward cone axis; files of the DG16M release)",
    )
    parser.add_argument(
        "--json", type=Path, default=None, metavar="OUT", help="write the full report as JSON"
    )
    parser.add_argument(
        "--strict",
        action="store_true",
        help="exit with status 1 unless every disagreement is explained by ambiguous normals",
    )
    parser.add_argument(
        "--max-combinations",
        type=int,
        default=256,
        help="face choices tried per disagreeing pair (default: 256)",
    )
    parser.add_argument(
        "--tolerance",
        type=float,
        default=1e-6,
        help="a contact is on a face within this distance in m (default: 1e-6)",
    )
    parser.add_argument(
        "--loss-rtol",
        type=float,
        default=1e-3,
        help="relative tolerance of the loss comparison on failing pairs (default: 1e-3)",
    )
    add_limit_argument(
        parser, "disagreeing pairs listed in the text output (default: 20; all in --json)", 20
    )
    parser.add_argument("--progress", action="store_true", help="show progress bars")
    parser.set_defaults(handler=_verify)


def _verify(args: argparse.Namespace) -> int:
    from dataset_gen.pipeline.verify import verify_file
    from dg16m_core.atomic import write_json_atomic

    report = verify_file(
        args.file,
        args.mesh,
        convention=args.convention,
        tolerance_m=args.tolerance,
        loss_rtol=args.loss_rtol,
        max_combinations=args.max_combinations,
        progress=args.progress,
    )
    print(report.format_text(limit=max(args.limit, 0)))
    if args.json is not None:
        write_json_atomic(args.json, report.to_dict())
        print(f"wrote {args.json}")
    if args.strict and not report.ok:
        return 1
    return 0
