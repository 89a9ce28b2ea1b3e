"""Versions: the installed package's, and the schema versions of the files it writes and reads."""

from __future__ import annotations

import importlib.metadata

SCHEMA_VERSION = 1
"""Version of the ``dg16m/`` group written by :func:`~dataset_gen.io.dg16m.write_dg16m`."""

SUPPORTED_SCHEMA_VERSIONS = (1,)
"""``dg16m/`` schema versions :func:`~dataset_gen.io.dg16m.read_dg16m` understands."""

MANIFEST_SCHEMA_VERSION = 1
"""Version of ``manifest.json`` written by :func:`~dataset_gen.io.manifest.write_manifest`."""

SUPPORTED_MANIFEST_VERSIONS = (1,)
"""Manifest schema versions :func:`~dataset_gen.io.manifest.read_manifest` understands."""


def package_version() -> str:
    """The installed dg16m version, or ``"0+unknown"`` when the distribution is not installed."""
    try:
        return importlib.metadata.version("dg16m")
    except importlib.metadata.PackageNotFoundError:
        return "0+unknown"
