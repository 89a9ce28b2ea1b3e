"""Issue 56: pictures a person can read: ``passes_per_object.png`` names each object on a
horizontal bar (or, for many objects, shows their distribution and the weakest ones), and panel
(f) of ``benchmark.png`` shows the weaker hand's contacts even when no hand lacks contact."""

from __future__ import annotations

import types

import numpy as np

from dataset_gen.pipeline.stats import PASSES_FEWEST, PASSES_LABELLED_OBJECTS, DatasetStats
from dataset_gen.pipeline.stats import _passes_figure as passes_figure
from dg16m_core.figures import new_figure
from dg16m_env.benchmark.report_plot import CONTACT_BINS, _plot_contacts


def tick_labels(ax) -> list[str]:
    return [label.get_text() for label in ax.get_yticklabels()]


def test_a_few_objects_are_named_on_horizontal_bars() -> None:
    stats = DatasetStats(
        objects=["bench-0000000", "tub-0000000"], passing=[2000, 362], failing=[2000, 2000]
    )
    fig = passes_figure(stats)
    (ax,) = fig.axes
    assert tick_labels(ax) == ["bench-0000000", "tub-0000000"]  # read across, not rotated
    assert all(label.get_rotation() == 0 for label in ax.get_yticklabels())
    widths = [patch.get_width() for patch in ax.patches]
    assert widths == [2000, 362, 2000, 2000]  # passing bars, then failing bars stacked on them
    assert "2 objects" in ax.get_title()


def test_many_objects_show_their_distribution_and_the_weakest() -> None:
    count = PASSES_LABELLED_OBJECTS + 60
    rng = np.random.default_rng(5)
    passing = [int(v) for v in rng.permutation(count) * 10]
    stats = DatasetStats(
        objects=[f"obj-{i:03d}" for i in range(count)], passing=passing, failing=[500] * count
    )
    fig = passes_figure(stats)
    left, right = fig.axes
    assert f"{count} objects" in left.get_title()
    weakest = sorted(range(count), key=lambda i: passing[i])[:PASSES_FEWEST]
    assert tick_labels(right) == [stats.objects[i] for i in weakest]


def test_panel_f_shows_contacts_when_no_hand_lacks_one() -> None:
    """All hands touch the object (the demo's case): the panel still has bars (the weaker
    hand's contact counts per arm), with 0 of N without contact in the legend."""
    contacts = np.array([[8, 9], [4, 8], [8, 8], [12, 3]])
    arms = {
        "fc_pass": np.array([True, True, False, False]),
        "random": ~np.array([1, 1, 0, 0], bool),
    }
    bench = types.SimpleNamespace(
        trials=types.SimpleNamespace(valid=np.ones(4, bool), contacts_after_close=contacts),
        arm_rows=lambda arm: arms[arm],
    )
    report = {
        "contacts_after_close": {
            "min_contacts": 1,
            "by_arm": {
                "fc_pass": {"valid": 2, "without_contact": 0, "share": 0.0},
                "random": {"valid": 2, "without_contact": 0, "share": 0.0},
            },
        }
    }
    ax = new_figure(6, 4).add_subplot()
    _plot_contacts(ax, bench, report)
    heights = {
        label: [p.get_height() for p in container]
        for container, label in zip(ax.containers, ["fc_pass", "random"], strict=True)
    }
    expected_pass = np.zeros(CONTACT_BINS + 1)
    expected_pass[[4, 8]] = 50.0  # weaker hands: 8 and 4
    expected_random = np.zeros(CONTACT_BINS + 1)
    expected_random[[3, 8]] = 50.0  # 8 and 3
    np.testing.assert_allclose(heights["fc_pass"], expected_pass)
    np.testing.assert_allclose(heights["random"], expected_random)
    legend = [text.get_text() for text in ax.get_legend().get_texts()]
    assert legend == ["fc_pass: 0 of 2 without contact", "random: 0 of 2 without contact"]
