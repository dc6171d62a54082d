"""docs/resplit_by_sample.py copies a dataset with a test split drawn by sample: as many hands and
non-hands as the original test split, people shared with training, every other byte the
same; the original is untouched and an existing target is refused."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tactile.dataset.reader import open_dataset


@pytest.fixture(scope="module")
def script(doc_script):
    return doc_script("resplit_by_sample")


def _splits(folder: Path) -> tuple[np.ndarray, np.ndarray]:
    with open_dataset(folder) as r:
        return np.asarray(r.splits["train"]), np.asarray(r.splits["test"])


def test_the_copy_holds_the_same_class_counts_drawn_by_sample(script, tiny_dataset, tmp_path):
    before = (tiny_dataset / "dataset.h5").read_bytes()
    train0, test0 = _splits(tiny_dataset)
    with open_dataset(tiny_dataset) as r:
        hand, subject = r["is_hand"][:].astype(bool), r["subject_id"][:]
        images = r["image"][:]
    counts = script.resplit_by_sample(tiny_dataset, tmp_path / "copy", seed=3)
    train, test = _splits(tmp_path / "copy")
    assert (tiny_dataset / "dataset.h5").read_bytes() == before
    np.testing.assert_array_equal(np.sort(np.concatenate([train, test])), np.arange(len(hand)))
    assert hand[test].sum() == hand[test0].sum() and (~hand[test]).sum() == (~hand[test0]).sum()
    assert counts["test_hands"] == hand[test].sum()
    # the original split shares no person; this draw does, as the counts say
    assert not set(subject[train0].tolist()) & set(subject[test0].tolist()) - {-1}
    seen = set(subject[train][hand[train]].tolist())
    shared = sum(s in seen for s in subject[test][hand[test]])
    assert counts["test_hands_of_training_people"] == shared
    assert counts["test_hands_of_training_people"] > 0
    with open_dataset(tmp_path / "copy") as r:
        np.testing.assert_array_equal(r["image"][:], images)
    # the same seed draws the same split; another seed another
    script.resplit_by_sample(tiny_dataset, tmp_path / "again", seed=3)
    np.testing.assert_array_equal(_splits(tmp_path / "again")[1], test)
    script.resplit_by_sample(tiny_dataset, tmp_path / "other", seed=4)
    assert not np.array_equal(_splits(tmp_path / "other")[1], test)


def test_an_existing_target_is_refused_untouched(script, tiny_dataset, tmp_path):
    target = tmp_path / "taken"
    target.mkdir()
    (target / "keep.txt").write_text("mine")
    with pytest.raises(SystemExit, match="exists"):
        script.resplit_by_sample(tiny_dataset, target)
    assert (target / "keep.txt").read_text() == "mine"
    with pytest.raises(SystemExit, match=r"no dataset\.h5"):
        script.resplit_by_sample(tmp_path / "nothing", tmp_path / "new")
    assert not (tmp_path / "new").exists()


def test_training_reads_the_new_split(script, tiny_dataset, tmp_path):
    from learn.folder import open_split

    script.resplit_by_sample(tiny_dataset, tmp_path / "copy", seed=0)
    _, test = _splits(tmp_path / "copy")
    ds = open_split(tmp_path / "copy", "test", "classify", (12, 18), None, 0, None)
    np.testing.assert_array_equal(np.sort(np.asarray(ds.indices)), test)
    assert not np.array_equal(test, _splits(tiny_dataset)[1])


def test_the_common_copy_tests_on_both_test_splits(script, tiny_dataset, tmp_path):
    script.resplit_by_sample(tiny_dataset, tmp_path / "bysample", seed=1)
    n = script.common_copy(tiny_dataset, tmp_path / "bysample", tmp_path / "common")
    want = sorted(
        set(_splits(tiny_dataset)[1].tolist()) & set(_splits(tmp_path / "bysample")[1].tolist())
    )
    train, test = _splits(tmp_path / "common")
    assert test.tolist() == want and n == len(want) > 0
    assert sorted([*train.tolist(), *test.tolist()]) == list(range(len(train) + len(test)))
    with pytest.raises(SystemExit, match="exists"):
        script.common_copy(tiny_dataset, tmp_path / "bysample", tmp_path / "common")
