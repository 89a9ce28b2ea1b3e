"""What a dataset is made of: :class:`DatasetRecipe` (object count, sources, splits, seeds).

The recipe and the generator's parameters are the dataset's parameters: its manifest records
both, and a rerun into the same folder must use the same ones (it resumes; other ones are
refused rather than mixed).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from dg16m_core.errors import Dg16mError

SOURCES: tuple[str, ...] = ("procedural", "sweethome3d", "pybullet")
"""Where objects can come from (:mod:`dataset_gen.collection.sources`)."""

DEFAULT_SOURCES: tuple[str, ...] = ("procedural", "sweethome3d")
"""The sources of a default build (pybullet's objects are an extra: ``pip install pybullet``)."""

SPLITS: tuple[str, ...] = ("train", "validation")

DG16M_OBJECTS = 4143
"""Objects in the DG16M release (the paper's dataset)."""


class DatasetError(Dg16mError, ValueError):
    """A dataset cannot be built as asked (bad recipe, a missing source, a folder of another
    dataset, an object shared with a benchmark)."""


@dataclass(frozen=True)
class DatasetRecipe:
    """What a dataset is made of.

    Attributes:
        objects: objects to build (at least; default :data:`DG16M_OBJECTS`). The non-procedural
            sources give what they have (every usable model not in a benchmark); procedural
            objects make up the rest, and more are added if some fail, until ``objects`` have
            grasps.
        sources: which of :data:`SOURCES` to draw from; must include ``"procedural"``.
        validation_fraction: share of objects in the ``validation`` split (by object; in [0,
            0.5]).
        split_seed: seed of the split assignment (:func:`dataset_gen.collection.splits.split_of`).
        procedural_seed: first seed of each procedural family (train seeds, disjoint from the
            benchmark's by construction and checked by hash).
        import_seed: seed of the sizes drawn for imported models (Sweet Home 3D, pybullet).
        sweethome3d_ids: only these Sweet Home 3D models (default None: every usable one that
            is not in a benchmark).
        pybullet_limit: only the first this many ``random_urdfs`` (default None: all 1,000).
    """

    objects: int = DG16M_OBJECTS
    sources: tuple[str, ...] = DEFAULT_SOURCES
    validation_fraction: float = 0.05
    split_seed: int = 0
    procedural_seed: int = 0
    import_seed: int = 0
    sweethome3d_ids: tuple[str, ...] | None = None
    pybullet_limit: int | None = None

    def __post_init__(self) -> None:
        for name in ("objects", "split_seed", "procedural_seed", "import_seed"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise DatasetError(f"{name}: expected a non-negative integer, found {value!r}")
        if self.objects < 1:
            raise DatasetError(f"objects: expected at least 1, found {self.objects}")
        sources = tuple(self.sources)
        unknown = [s for s in sources if s not in SOURCES]
        if unknown or len(set(sources)) != len(sources) or "procedural" not in sources:
            raise DatasetError(
                f"sources: expected distinct names among {', '.join(SOURCES)} including "
                f"procedural, found {', '.join(sources) or 'none'}"
            )
        object.__setattr__(self, "sources", tuple(s for s in SOURCES if s in sources))
        if self.sweethome3d_ids is not None:
            ids = tuple(self.sweethome3d_ids)
            if not ids or not all(isinstance(i, str) and i for i in ids):
                raise DatasetError(
                    f"sweethome3d_ids: expected None or model ids, found {self.sweethome3d_ids!r}"
                )
            object.__setattr__(self, "sweethome3d_ids", tuple(sorted(set(ids))))
        limit = self.pybullet_limit
        if limit is not None and (
            isinstance(limit, bool) or not isinstance(limit, int) or limit < 1
        ):
            raise DatasetError(f"pybullet_limit: expected None or an integer >= 1, found {limit!r}")
        fraction = self.validation_fraction
        if (
            isinstance(fraction, bool)
            or not isinstance(fraction, (int, float))
            or not 0.0 <= fraction <= 0.5
        ):
            raise DatasetError(
                f"validation_fraction: expected a number in [0, 0.5], found {fraction!r}"
            )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields (the manifest's ``parameters.recipe``)."""
        out = asdict(self)
        out["sources"] = list(self.sources)
        if self.sweethome3d_ids is not None:
            out["sweethome3d_ids"] = list(self.sweethome3d_ids)
        out["validation_fraction"] = float(self.validation_fraction)
        return out
