"""A model scored on another dataset of the same subject pool: the shared subjects and object
instances are found (against sets built here from the ids), and the report says the scores are
not held out; the same folder, or another pool, is never flagged."""

from __future__ import annotations

import json
import shutil

import h5py
import numpy as np

from learn.eval_report import write_report
from learn.evaluate import evaluate_checkpoint
from learn.leakage import shared_groups
from tactile.dataset.reader import DatasetReader


def resplit(src, dst, test: np.ndarray):
    """A copy of dataset ``src`` at ``dst`` whose test split is the sample indices ``test``."""
    shutil.copytree(src, dst)
    with h5py.File(dst / "dataset.h5", "r+") as f:
        n = len(f["splits/train"]) + len(f["splits/test"])
        train = np.setdiff1d(np.arange(n), test)
        for name, idx in (("train", train), ("test", np.sort(test))):
            del f[f"splits/{name}"]
            f[f"splits/{name}"] = idx.astype(np.int64)
    return dst


def test_shared_groups_against_the_ids(tiny_dataset, tmp_path):
    with DatasetReader(tiny_dataset) as ds:
        train = ds.splits["train"]
        subject, instance = ds.subject_id[:], ds.instance_id[:]
    other = resplit(tiny_dataset, tmp_path / "other", train[::2])  # test: half of our train
    shared = shared_groups(tiny_dataset, other)
    test = train[::2]
    want_s = sorted(set(subject[test].tolist()) - {-1})
    want_i = sorted(set(instance[test].tolist()) - {-1})
    assert shared["subjects"] == want_s and shared["instances"] == want_i
    assert shared["test_samples"] == shared["n_test"] == len(test)  # every one was trained on
    # the dataset's own split is disjoint by construction: nothing to check, None
    assert shared_groups(tiny_dataset, tiny_dataset) is None
    assert shared_groups(tiny_dataset / "dataset.h5", tiny_dataset) is None
    # another pool (another seed in the manifest): ids name other people, None
    manifest = json.loads((other / "manifest.json").read_text())
    (other / "manifest.json").write_text(json.dumps({**manifest, "seed": manifest["seed"] + 1}))
    assert shared_groups(tiny_dataset, other) is None


def as_generated(folder, **changes):
    """Make ``folder``'s manifest look like the generator's (subject and instance pool keys),
    with ``changes`` to its seed / part."""
    path = folder / "manifest.json"
    manifest = json.loads(path.read_text())
    config = {**manifest["config"], "n_subjects": 90, "instances_per_kind": 20}
    path.write_text(json.dumps({**manifest, "config": config, **changes}))
    return folder


def test_generated_sets_share_subjects_across_parts_and_instances_across_seeds(tiny_dataset,
                                                                              tmp_path):
    """The generator's subjects depend on (seed, id), its instances on the id alone: another part
    of one seed can share both, another seed only the instances."""
    with DatasetReader(tiny_dataset) as ds:
        train = ds.splits["train"]
        subject, instance = ds.subject_id[:], ds.instance_id[:]
    test = train[::2]
    mine = as_generated(resplit(tiny_dataset, tmp_path / "mine", tiny_ds_test(tiny_dataset)))
    want_s = sorted(set(subject[test].tolist()) - {-1})
    want_i = sorted(set(instance[test].tolist()) - {-1})
    part = as_generated(resplit(tiny_dataset, tmp_path / "part", test), part="forearm_x2")
    shared = shared_groups(mine, part)
    assert shared["subjects"] == want_s and shared["instances"] == want_i
    assert shared["test_samples"] == len(test)
    seed = as_generated(resplit(tiny_dataset, tmp_path / "seed", test), seed=99)
    shared = shared_groups(mine, seed)
    assert shared["subjects"] == [] and shared["instances"] == want_i
    assert shared["test_samples"] == int((instance[test] >= 0).sum()) > 0


def tiny_ds_test(folder) -> np.ndarray:
    with DatasetReader(folder) as ds:
        return ds.splits["test"]


def test_report_flags_scores_that_are_not_held_out(tiny_dataset, checkpoints, tmp_path):
    with DatasetReader(tiny_dataset) as ds:
        own_test = ds.splits["test"]
        train = ds.splits["train"]
    row = evaluate_checkpoint(checkpoints["handsnet"], tiny_dataset, time_runs=2)
    assert row["shared_with_training"] is None
    clean = resplit(tiny_dataset, tmp_path / "clean", own_test)  # same split, other folder
    assert evaluate_checkpoint(checkpoints["handsnet"], clean,
                               time_runs=2)["shared_with_training"]["test_samples"] == 0
    leaky = resplit(tiny_dataset, tmp_path / "leaky", np.sort(np.r_[own_test, train[:8]]))
    bad = evaluate_checkpoint(checkpoints["handsnet"], leaky, time_runs=2)
    with DatasetReader(tiny_dataset) as ds:
        subject, instance = ds.subject_id[:], ds.instance_id[:]
    seen_s, seen_i = set(subject[train].tolist()) - {-1}, set(instance[train].tolist()) - {-1}
    test = np.sort(np.r_[own_test, train[:8]])
    expected = sum(subject[i] in seen_s or instance[i] in seen_i for i in test)
    assert bad["shared_with_training"]["test_samples"] == expected >= 8
    text = write_report([bad], tmp_path / "r.md").read_text()
    assert f"**Not held out**: {expected} of the {len(test)} test samples" in text
    kinds = (("subjects", any(subject[i] in seen_s for i in test)),
             ("object instances", any(instance[i] in seen_i for i in test)))
    what = " or ".join(w for w, hit in kinds if hit)
    assert what and f"not held out: {expected} test samples share its {what} |" in text
