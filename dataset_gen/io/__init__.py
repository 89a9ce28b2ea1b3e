"""File formats: DG16M release grasp files, ACRONYM grasp files, dataset manifests.

Every reader validates what it reads and raises :class:`~dg16m_core.errors.GraspFileError` naming
the file, the key, what was expected and what was found. Every writer goes through
:func:`dg16m_core.atomic.atomic_path`, so a destination is either its old version or complete.
Nothing is ever unpickled: HDF5 datasets are checked for a numeric dtype before their data is
read, and the only string data read from HDF5 is ``object/file`` (and ACRONYM's ``gripper/type``).

One module per format, each documenting its schema; every public name is importable from here
(``from dataset_gen import io; io.read_dg16m(path)``):

=================================  ===========================================================
module                             contents
=================================  ===========================================================
:mod:`dataset_gen.io.dg16m`        DG16M release schema and dg16m extensions (grasp frame, keys,
                                   :class:`DualGraspSet`, :func:`read_dg16m`, :func:`write_dg16m`)
:mod:`dataset_gen.io.acronym`      ACRONYM files (:class:`AcronymGrasps`, :func:`read_acronym`,
                                   frame conversion :func:`acronym_to_dg16m`)
:mod:`dataset_gen.io.manifest`     ``manifest.json`` of a dataset folder
:mod:`dataset_gen.io.versions`     package version and the schema versions written and read
:mod:`dataset_gen.io.detect`       :func:`detect_format` of a grasp file
``dataset_gen.io._checks``         validation shared by the formats
``dataset_gen.io._hdf5``           safe HDF5 reading, deterministic ``write_array``
=================================  ===========================================================

Floor 1 of :mod:`dataset_gen`. May import: :mod:`dg16m_core`, :mod:`dataset_gen.objects` and
this folder.
"""

from __future__ import annotations

from ._checks import RIGID_ATOL, PathLike
from ._hdf5 import CHUNK_BYTES, hdf5_content_problem, open_hdf5, write_array
from .acronym import (
    ACRONYM_REQUIRED_KEYS,
    ACRONYM_TO_DG16M,
    AcronymGrasps,
    acronym_to_dg16m,
    dg16m_to_acronym,
    read_acronym,
)
from .detect import detect_format
from .dg16m import (
    DEFAULT_GZIP_LEVEL,
    EXTRAS_GROUP,
    LOSS_ATOL,
    RELEASE_KEYS,
    DualGraspSet,
    read_dg16m,
    write_dg16m,
)
from .manifest import (
    MANIFEST_FORMAT,
    MANIFEST_KINDS,
    MANIFEST_NAME,
    MANIFEST_STATUSES,
    failed_entries,
    failure_lines,
    manifest_entry_path,
    new_manifest,
    read_manifest,
    update_manifest_entry,
    validate_manifest,
    write_manifest,
)
from .versions import (
    MANIFEST_SCHEMA_VERSION,
    SCHEMA_VERSION,
    SUPPORTED_MANIFEST_VERSIONS,
    SUPPORTED_SCHEMA_VERSIONS,
    package_version,
)

__all__ = [
    "ACRONYM_REQUIRED_KEYS",
    "ACRONYM_TO_DG16M",
    "CHUNK_BYTES",
    "DEFAULT_GZIP_LEVEL",
    "EXTRAS_GROUP",
    "LOSS_ATOL",
    "MANIFEST_FORMAT",
    "MANIFEST_KINDS",
    "MANIFEST_NAME",
    "MANIFEST_SCHEMA_VERSION",
    "MANIFEST_STATUSES",
    "RELEASE_KEYS",
    "RIGID_ATOL",
    "SCHEMA_VERSION",
    "SUPPORTED_MANIFEST_VERSIONS",
    "SUPPORTED_SCHEMA_VERSIONS",
    "AcronymGrasps",
    "DualGraspSet",
    "PathLike",
    "acronym_to_dg16m",
    "detect_format",
    "dg16m_to_acronym",
    "failed_entries",
    "failure_lines",
    "hdf5_content_problem",
    "manifest_entry_path",
    "new_manifest",
    "open_hdf5",
    "package_version",
    "read_acronym",
    "read_dg16m",
    "read_manifest",
    "update_manifest_entry",
    "validate_manifest",
    "write_array",
    "write_dg16m",
    "write_manifest",
]
