"""Test helpers shared by the mesh tests (importable from tests/ as ``shipped_meshes``): the
real furniture meshes shipped in ``tests/data/meshes`` and coarse CoACD settings that decompose
them, or a small solid, in about a second."""

from __future__ import annotations

from pathlib import Path

from dataset_gen.objects.decomposition import DecompositionParameters

MESHES = Path(__file__).parent / "data" / "meshes"
"""The shipped real meshes (couch, dining chair, dining table; metres; see NOTICE.md there)."""

FAST = DecompositionParameters(
    threshold=0.05,
    preprocess_resolution=20,
    resolution=500,
    mcts_nodes=10,
    mcts_iterations=20,
    mcts_max_depth=2,
)
"""Coarse CoACD settings: quick, not faithful (the tests of faithfulness use the defaults)."""
