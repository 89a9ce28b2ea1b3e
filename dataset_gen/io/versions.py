"""Versions: the installed package's, and the schema versions of the files it writes and reads."""

from __future__ import annotations

from dg16m_core.distribution import package_version

__all__ = [
    "MANIFEST_SCHEMA_VERSION",
    "SCHEMA_VERSION",
    "SUPPORTED_MANIFEST_VERSIONS",
    "SUPPORTED_SCHEMA_VERSIONS",
    "package_version",
]

SCHEMA_VERSION = 1
"""Version of the ``dg16m/`` group written by :func:`~dataset_gen.io.dg16m.write_dg16m`."""

SUPPORTED_SCHEMA_VERSIONS = (1,)
"""``dg16m/`` schema versions :func:`~dataset_gen.io.dg16m.read_dg16m` understands."""

MANIFEST_SCHEMA_VERSION = 1
"""Version of ``manifest.json`` written by :func:`~dataset_gen.io.manifest.write_manifest`."""

SUPPORTED_MANIFEST_VERSIONS = (1,)
"""Manifest schema versions :func:`~dataset_gen.io.manifest.read_manifest` understands."""
