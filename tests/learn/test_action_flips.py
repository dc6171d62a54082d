"""Mirror pairs under the training flips: a mirrored view of a press turns a clockwise twist into a
counter-clockwise one and a push to the left into one to the right; the 180-degree turn and the
other actions keep their labels."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from learn.data.folder import HAND_NAMES
from learn.data.load import TensorData
from learn.inputs import PAPER_VIEWS, flip_view, is_mirror, mirror_classes, targets_in_view
from learn.train.loop import get_batch
from tactile.images.labels import CLASS_NAMES

ACTIONS = (
    "grasp",
    "grasp_twist_cw",
    "grasp_twist_ccw",
    "push_left",
    "push_right",
    "push_away",
    "pull",
    "free",
)
#: written out by hand: cw <-> ccw (1, 2), left <-> right (3, 4), the others stay
SWAPPED = [0, 2, 1, 4, 3, 5, 6, 7]


def test_mirror_classes_of_the_actions():
    assert mirror_classes(ACTIONS).tolist() == SWAPPED
    assert mirror_classes(
        ("pull", "push_right", "twist_ccw", "push_left", "twist_cw")
    ).tolist() == [
        0,
        3,
        4,
        1,
        2,
    ]


def test_classes_without_mirror_pairs_stay():
    assert mirror_classes(HAND_NAMES) is None
    assert mirror_classes(CLASS_NAMES) is None
    assert mirror_classes(("push_left", "pull")) is None  # no partner: nothing to swap to


def test_mirror_views():
    assert [is_mirror(v) for v in (0, 1, 2, 3)] == [False, True, True, False]


@pytest.mark.parametrize("view", [0, 1, 2, 3])
def test_targets_in_view(view):
    y = np.arange(8)
    mirror = np.array(SWAPPED)
    expected = SWAPPED if view in (1, 2) else list(range(8))
    assert targets_in_view(y, view, mirror).tolist() == expected
    assert targets_in_view(y, view, None).tolist() == list(range(8))
    labels = np.arange(12).reshape(3, 4)
    np.testing.assert_array_equal(targets_in_view(labels, view, mirror), flip_view(labels, view))


def test_training_batches_swap_the_labels_of_mirrored_views():
    """Every (sequence, view) item of a batch: frames flipped on their last two axes, the label
    swapped in views 1 and 2 only."""
    g = torch.Generator().manual_seed(0)
    x = torch.rand(8, 5, 1, 6, 7, generator=g)
    data = TensorData(x, torch.arange(8), torch.tensor(SWAPPED))
    views = torch.tensor(PAPER_VIEWS)
    items = torch.arange(24)
    xb, yb = get_batch(data, items, views)
    for item in range(24):
        s, v = item // 3, PAPER_VIEWS[item % 3]
        torch.testing.assert_close(xb[item], x[s].flip([(), (-1,), (-2,)][v]) if v else x[s])
        assert int(yb[item]) == (SWAPPED[s] if v in (1, 2) else s)


def test_without_mirror_pairs_batches_keep_their_labels():
    data = TensorData(torch.rand(4, 1, 6, 7), torch.tensor([0, 1, 1, 0]))
    _, yb = get_batch(data, torch.arange(12), torch.tensor(PAPER_VIEWS))
    assert yb.tolist() == [0, 0, 0, 1, 1, 1, 1, 1, 1, 0, 0, 0]
