"""A model scored on another dataset of the same subject pool: the shared subjects and object
instances are found (against sets built here from the ids), and the report says the scores are
not held out; another pool is never flagged, nor the same folder unless its own split shares
people (a split by sample)."""

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


def test_generated_sets_share_subjects_across_parts_and_instances_across_seeds(
    tiny_dataset, tmp_path
):
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
    own = row["shared_with_training"]  # its own split, checked: no person on both sides
    assert own["test_samples"] == own["own_split_samples"] == 0 and own["n_test"] == len(own_test)
    clean = resplit(tiny_dataset, tmp_path / "clean", own_test)  # same split, other folder
    assert (
        evaluate_checkpoint(checkpoints["handsnet"], clean, time_runs=2)["shared_with_training"][
            "test_samples"
        ]
        == 0
    )
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
    kinds = (
        ("subjects", any(subject[i] in seen_s for i in test)),
        ("object instances", any(instance[i] in seen_i for i in test)),
    )
    what = " or ".join(w for w, hit in kinds if hit)
    assert what and f"not held out: {expected} test samples share its {what} |" in text


def _expected_hits(tiny_dataset, train_sets: list[np.ndarray], test: np.ndarray) -> int:
    """Samples of ``test`` whose subject or instance is in any of ``train_sets`` (indices into
    the tiny dataset, which every resplit copy shares), counted from the raw ids."""
    with DatasetReader(tiny_dataset) as ds:
        subject, instance = ds.subject_id[:], ds.instance_id[:]
    train = np.concatenate(train_sets)
    seen_s, seen_i = set(subject[train].tolist()) - {-1}, set(instance[train].tolist()) - {-1}
    return sum(subject[i] in seen_s or instance[i] in seen_i for i in test)


def test_shared_groups_pools_several_training_sets(tiny_dataset, tmp_path):
    with DatasetReader(tiny_dataset) as ds:
        train, test = ds.splits["train"], ds.splits["test"]
    n = len(train) + len(test)
    a = resplit(tiny_dataset, tmp_path / "a", np.sort(np.r_[test, train[: len(train) // 2]]))
    b = resplit(tiny_dataset, tmp_path / "b", np.sort(np.r_[test, train[len(train) // 2 :]]))
    target = resplit(tiny_dataset, tmp_path / "t", train)  # its test: the tiny set's train
    a_train = np.setdiff1d(np.arange(n), np.r_[test, train[: len(train) // 2]])
    b_train = np.setdiff1d(np.arange(n), np.r_[test, train[len(train) // 2 :]])
    one, both = shared_groups(a, target), shared_groups([a, b, tiny_dataset], target)
    assert one["test_samples"] == _expected_hits(tiny_dataset, [a_train], train)
    assert both["test_samples"] == _expected_hits(tiny_dataset, [a_train, b_train], train)
    assert both["test_samples"] == len(train) > one["test_samples"]
    assert shared_groups([target, target / "dataset.h5"], target) is None  # its own split


def test_a_model_started_from_a_leaky_checkpoint_is_flagged(tiny_dataset, tiny_run, tmp_path):
    """A network fine-tuned on the tiny set from one pretrained on a copy whose training split
    holds the tiny set's test people: --init warns, and evaluation says it is not held out,
    though its own training data is the tiny set's train split."""
    import pytest

    from learn.finetune import check_init
    from learn.train import fit, load_data

    with DatasetReader(tiny_dataset) as ds:
        train, test = ds.splits["train"], ds.splits["test"]
    n = len(train) + len(test)
    other = resplit(tiny_dataset, tmp_path / "other", train[::2])  # trains on our test people
    run = tiny_run("handsnet", epochs=1)
    fit(run, load_data(other, run), tmp_path / "pre", progress=False)
    with pytest.warns(UserWarning, match="will not be held out"):
        check_init(run, tmp_path / "pre" / "best.pt", tiny_dataset)
    fit(
        run,
        load_data(tiny_dataset, run),
        tmp_path / "ft",
        progress=False,
        init_from=tmp_path / "pre" / "best.pt",
    )
    row = evaluate_checkpoint(tmp_path / "ft" / "best.pt", tiny_dataset, time_runs=2)
    expected = _expected_hits(tiny_dataset, [np.setdiff1d(np.arange(n), train[::2])], test)
    assert row["shared_with_training"]["test_samples"] == expected > 0
    assert "**Not held out**" in write_report([row], tmp_path / "r.md").read_text()
    # the same network started from one trained on the tiny set itself is held out
    fit(
        run,
        load_data(tiny_dataset, run),
        tmp_path / "ft2",
        progress=False,
        init_from=tmp_path / "ft" / "best.pt",
    )
    row2 = evaluate_checkpoint(tmp_path / "ft2" / "best.pt", tiny_dataset, time_runs=2)
    assert row2["shared_with_training"]["test_samples"] == expected  # the grandparent's data


def test_the_train_command_reads_its_init_checkpoint_once(
    tiny_dataset, checkpoints, tmp_path, monkeypatch
):
    """--init is checked before the data load; fit reuses that checkpoint for its weights and its
    lineage rather than reading the file again (it was read three times)."""
    import torch
    import typer
    from typer.testing import CliRunner

    from learn.cli import register

    reads, load = [], torch.load
    monkeypatch.setattr(torch, "load", lambda f, *a, **k: reads.append(str(f)) or load(f, *a, **k))
    app = typer.Typer()
    register(app)
    config = tmp_path / "run.toml"
    config.write_text("threads = 1\n[model]\ninput_size = [32, 48]\n[train]\nepochs = 1\n")
    res = CliRunner().invoke(
        app,
        [
            "train",
            str(tiny_dataset),
            "--config",
            str(config),
            "--no-progress",
            "--out",
            str(tmp_path / "ft"),
            "--init",
            str(checkpoints["handsnet"]),
        ],
    )
    assert res.exit_code == 0, res.output
    assert reads.count(str(checkpoints["handsnet"])) == 1, reads
    ft = load(tmp_path / "ft" / "best.pt", weights_only=False)
    assert ft["init"] == str(checkpoints["handsnet"])
    assert ft["ancestry"] == [load(checkpoints["handsnet"], weights_only=False)["data"]]


def test_init_loading_nothing_is_refused_and_a_vgg_encoder_loads(
    tiny_dataset, tiny_run, checkpoints, tmp_path
):
    import pytest

    from learn.finetune import check_init
    from learn.train import fit, load_data
    from tactile.errors import ConfigError

    with pytest.raises(ConfigError, match=r"none of its \d+ tensors fits a segnet"):
        check_init(tiny_run("segnet"), checkpoints["handsnet"], tiny_dataset)
    vgg = tiny_run("vgg16", epochs=1)
    fit(vgg, load_data(tiny_dataset, vgg), tmp_path / "vgg", progress=False)
    got, ckpt = check_init(tiny_run("segnet"), tmp_path / "vgg" / "best.pt", tiny_dataset)
    assert ckpt["config"]["model"]["arch"] == "vgg16"
    assert got.loaded and all(k.startswith("encoder.") for k in got.loaded)
    assert "decoder" in got.summary() and "encoder" not in got.summary().split(";")[1]


def test_a_segmenter_is_judged_on_the_hands_it_is_scored_on(tiny_dataset, checkpoints, tmp_path):
    """A test split holding training objects is not held out for a classifier, but a segmenter
    scores the hands only, and those are the dataset's own test hands."""
    with DatasetReader(tiny_dataset) as ds:
        own_test, train = ds.splits["test"], ds.splits["train"]
        is_hand = ds.is_hand[:].astype(bool)
    objects = train[~is_hand[train]][:6]
    mixed = resplit(tiny_dataset, tmp_path / "mixed", np.sort(np.r_[own_test, objects]))
    seg = evaluate_checkpoint(checkpoints["segnet"], mixed, time_runs=2)
    assert seg["n_test"] == int(is_hand[own_test].sum())
    assert seg["shared_with_training"] == {
        "subjects": [],
        "instances": [],
        "test_samples": 0,
        "n_test": seg["n_test"],
        "own_split_samples": 0,
    }
    cls = evaluate_checkpoint(checkpoints["handsnet"], mixed, time_runs=2)
    assert cls["shared_with_training"]["test_samples"] >= len(objects)
    # so does --init: a warning for the classifier, none for the segmenter
    import warnings

    import pytest

    from learn.finetune import check_init

    from .conftest import make_run

    with pytest.warns(UserWarning, match="will not be held out"):
        check_init(make_run("handsnet"), checkpoints["handsnet"], mixed)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_init(make_run("segnet"), checkpoints["segnet"], mixed)


def test_a_split_by_sample_is_flagged_on_its_own_data(tiny_dataset, tiny_run, tmp_path):
    """A model trained and scored on one dataset whose test split holds samples of its training
    people (docs/resplit_by_sample.py's copy): evaluation counts them from the raw ids and the
    report names the dataset's own split; shared_groups without own_split stays silent."""
    from learn.train import fit, load_data

    with DatasetReader(tiny_dataset) as ds:
        train, test = ds.splits["train"], ds.splits["test"]
    mixed = np.sort(np.r_[test[::2], train[::3]])  # half its test people's, some of training's
    copy = resplit(tiny_dataset, tmp_path / "bysample", mixed)
    run = tiny_run("handsnet", epochs=1)
    fit(run, load_data(copy, run), tmp_path / "m", progress=False)
    row = evaluate_checkpoint(tmp_path / "m" / "best.pt", copy, time_runs=2)
    n = len(train) + len(test)
    expected = _expected_hits(tiny_dataset, [np.setdiff1d(np.arange(n), mixed)], mixed)
    shared = row["shared_with_training"]
    assert shared["test_samples"] == shared["own_split_samples"] == expected > 0
    assert shared["n_test"] == len(mixed)
    text = write_report([row], tmp_path / "r.md").read_text()
    assert f"**Not held out**: {expected} of the {len(mixed)} test samples" in text
    assert "own train and test splits share them" in text
    assert shared_groups(copy, copy) is None


def test_training_on_a_split_by_sample_warns(tiny_dataset, tmp_path):
    """`handskin train` says before training that a dataset's own split shares people (a
    segmenter: among the test hands it will be scored on), and says nothing on a split by
    person."""
    import typer
    from typer.testing import CliRunner

    from learn.cli import register

    app = typer.Typer()
    register(app)
    with DatasetReader(tiny_dataset) as ds:
        train, test = ds.splits["train"], ds.splits["test"]
        hand = ds.is_hand[:].astype(bool)
    mixed = np.sort(np.r_[test[::2], train[::3]])
    copy = resplit(tiny_dataset, tmp_path / "bysample", mixed)
    config = tmp_path / "run.toml"
    config.write_text("threads = 1\n[model]\ninput_size = [32, 48]\n[train]\nepochs = 1\n")
    n = len(train) + len(test)
    others = [np.setdiff1d(np.arange(n), mixed)]
    for arch, scored, start in (
        ("handsnet", mixed, []),
        ("segnet", mixed[hand[mixed]], ["--no-pretrain-encoder"]),
    ):
        res = CliRunner().invoke(
            app,
            [
                "train",
                str(copy),
                "--out",
                str(tmp_path / arch),
                "--arch",
                arch,
                "--config",
                str(config),
                "--no-progress",
                *start,
            ],
        )
        assert res.exit_code == 0, res.output
        expected = _expected_hits(tiny_dataset, others, scored)
        assert f"warning: {expected} of the {len(scored)} test samples of {copy}" in res.stderr
    res = CliRunner().invoke(
        app,
        [
            "train",
            str(tiny_dataset),
            "--out",
            str(tmp_path / "clean"),
            "--config",
            str(config),
            "--no-progress",
        ],
    )
    assert res.exit_code == 0, res.output
    assert "warning" not in res.stderr
