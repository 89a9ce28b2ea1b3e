"""The installed ``dg16m`` distribution: its name and version.

Standard library only: the command line reads its version (``dg16m --version``) from here
without importing the file formats (:mod:`dataset_gen.io` re-exports :func:`package_version`).
"""

from __future__ import annotations

from importlib import metadata

DISTRIBUTION = "dg16m"
"""The distribution's name on the package index (``pip install dg16m``)."""


def package_version() -> str:
    """The installed dg16m version, or ``"0+unknown"`` when the distribution is not installed."""
    try:
        return metadata.version(DISTRIBUTION)
    except metadata.PackageNotFoundError:
        return "0+unknown"
