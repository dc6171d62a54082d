"""`handskin experiment fidelity` end to end on a tiny scale (plate part, a dozen samples per
setting, 2 epochs), checked against independent references: a per-image re-evaluation of every
saved model, the datasets' own manifests, the rule recomputed by brute force, and invariants
(storing sequences changes no image; the test set shares no person or object with training)."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torch")
pytest.importorskip("mujoco")

from experiments import fidelity_report as F
from experiments import fidelity_settings as FS
from experiments.fidelity import FidelityPlan, run_fidelity
from tactile.errors import ConfigError

SETTINGS = ["cheapest", "default", "sequences", "solver_1"]  # solver_1: MuJoCo warns
PLAN = FidelityPlan(n=16, epochs=2, image_px=(32, 48), workers=1, seed=5)


def tiny_base():
    """The plate with a few people and objects (as `sim.generate.tiny`), full-length presses."""
    from sim.episode.runner import EpisodeConfig
    from sim.generate.config import GenerateConfig

    return GenerateConfig(
        part="plate", n_subjects=4, instances_per_kind=2, episode=EpisodeConfig(max_attempts=20)
    )


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    import torch

    torch.set_num_threads(1)
    out = tmp_path_factory.mktemp("fidelity") / "out"
    with pytest.MonkeyPatch.context() as mp:  # in its own cwd: see the MUJOCO_LOG.TXT test
        mp.chdir(out.parent)
        results = run_fidelity(out, PLAN, settings=SETTINGS, base=tiny_base(), progress=False)
    return out, results


def _rows(results):
    return {r["name"]: r for r in results["settings"]}


def _read(folder, field):
    from tactile.dataset.reader import open_dataset

    with open_dataset(folder) as ds:
        return ds[field][:]


def test_report_folder_has_tables_and_a_chart(run):
    import matplotlib.image as mpimg

    out, results = run
    text = (out / "report.md").read_text()
    for title in (
        "## Protocol",
        "## Settings, speed and accuracy",
        "## Choice of default",
        "**Rule.**",
        "**Outcome.**",
    ):
        assert title in text
    for name in SETTINGS:
        assert f"| `{name}` |" in text
    assert json.loads((out / "results.json").read_text())["results"] == json.loads(
        json.dumps(results)
    )
    img = mpimg.imread(out / "speed_accuracy.png")
    colours = np.unique(img[..., :3].reshape(-1, 3).round(2), axis=0)
    assert img.std() > 0.05 and len(colours) > 20


def test_every_accuracy_equals_a_per_image_reevaluation(run, near_ties):
    import torch

    from learn.inputs import net_input
    from learn.train.checkpoint import LAST, load_checkpoint, model_from_checkpoint
    from tactile.dataset.reader import open_dataset

    out, results = run
    test_dir = results["test_set"]["dataset"]
    with open_dataset(test_dir) as ds:
        test = ds.splits["test"]
        images = [net_input(ds.image[i], PLAN.image_px, "classify") for i in test]
        truth = ds.is_hand[:][test].astype(np.int64)
    assert len(test) == results["test_set"]["n_test"] and 0 < truth.sum() < len(truth)
    for row in results["settings"]:
        folder = row["dataset"].rsplit("/", 1)[1]
        (ckpt,) = (out / "models").glob(f"handsnet-{folder}-*/{LAST}")
        model = model_from_checkpoint(load_checkpoint(ckpt))[0]
        with torch.no_grad():
            logits = torch.cat([model(torch.from_numpy(x)[None, None]) for x in images])
        right = np.mean(logits.argmax(1).numpy() == truth)
        near_ties.assert_rate(row["accuracy_pct"] / 100, right, logits)


def test_each_dataset_was_made_with_its_setting(run):
    from tactile.dataset.manifest import read_manifest

    _, results = run
    for row in results["settings"]:
        cfg = read_manifest(Path(row["dataset"]))["config"]
        assert (cfg["n"], cfg["seed"], cfg["part"]) == (PLAN.n, PLAN.seed, "plate")
        for key, value in FS.BY_NAME[row["name"]].changes.items():
            node = cfg
            for k in key.split("."):
                node = node[k]
            assert node == value, (row["name"], key)
    test_cfg = read_manifest(Path(results["test_set"]["dataset"]))["config"]
    rich = FS.BY_NAME[FS.RICHEST].changes["episode.timestep_s"]
    assert test_cfg["episode"]["timestep_s"] == rich
    assert (test_cfg["seed"], test_cfg["n"]) == (PLAN.seed, PLAN.n)


def test_unstable_attempts_are_rejected_without_a_mujoco_log_file(run):
    """With one solver iteration some presses go unstable (MuJoCo warns; the attempt is retried
    with a new seed): the warnings are counted as rejects and leave no MUJOCO_LOG.TXT behind."""
    from tactile.dataset.reader import open_dataset

    out, results = run
    warned = 0
    for row in [*results["settings"], results["test_set"]]:
        with open_dataset(row["dataset"]) as ds:
            warned += ds.attrs["rejects"].get("warning", 0)
    assert warned > 0
    assert not (out.parent / "MUJOCO_LOG.TXT").exists()


def test_storing_sequences_changes_no_image_and_no_accuracy(run):
    rows = _rows(run[1])
    seq, default = rows["sequences"]["dataset"], rows["default"]["dataset"]
    assert np.array_equal(_read(seq, "image"), _read(default, "image"))
    assert rows["sequences"]["accuracy_pct"] == rows["default"]["accuracy_pct"]


def test_no_person_or_object_of_the_test_split_is_trained_on(run):
    """Trained samples are re-selected here from the contactor descriptions (a person's hand
    dimensions, an object's geometry): none may appear in the test split."""
    from tactile.dataset.reader import open_dataset

    def descriptions(folder, indices=None):
        with open_dataset(folder) as ds:
            raw = ds["contactor"][:]
        chosen = raw if indices is None else raw[indices]
        return [
            json.dumps({k: v for k, v in json.loads(c).items() if k != "press"}, sort_keys=True)
            for c in chosen
        ]

    _, results = run
    test_dir = results["test_set"]["dataset"]
    with open_dataset(test_dir) as ds:
        test = set(descriptions(test_dir, ds.splits["test"]))
    for row in results["settings"]:
        mine = descriptions(row["dataset"])
        trained = [d for d in mine if d not in test]
        assert len(trained) == row["n_train"], row["name"]
        assert 0 < row["n_train"] < PLAN.n


def test_reported_speeds_are_samples_over_wall_and_cpu_time(run):
    for row in run[1]["settings"]:
        assert row["n_computed"] == PLAN.n and row["workers"] == 1
        assert row["samples_per_s"] == pytest.approx(row["n_computed"] / row["wall_s"])
        assert row["per_core"] == pytest.approx(row["n_computed"] / row["cpu_s"])
        assert 0 < row["cpu_s"]


def test_choice_is_the_fastest_within_tolerance_by_brute_force(run):
    out, results = run
    rows, choice = results["settings"], results["choice"]
    best = max(r["accuracy_pct"] for r in rows)
    p = best / 100
    n_test = results["test_set"]["n_test"]
    tol = max(F.MIN_TOL_PT, 1.959963984540054 * 100 * np.sqrt(p * (1 - p) / n_test))
    ok = [r for r in rows if r["accuracy_pct"] >= best - tol]
    ref = next(r["prints"] for r in rows if r["name"] == "default")
    same = [r for r in ok if all(lo <= r["prints"][k][0] <= hi for k, (_, lo, hi) in ref.items())]
    assert choice["name"] == max(same or ok, key=lambda r: r["per_core"])["name"]
    assert f"**Outcome.** `{choice['name']}`" in (out / "report.md").read_text()


def test_print_statistics_are_the_datasets_own_counts(run):
    """Each setting's mean active taxels and force per contactor kind, recounted from its
    dataset's arrays, with a spread around it."""
    from tactile.dataset.reader import open_dataset

    for row in run[1]["settings"]:
        with open_dataset(row["dataset"]) as ds:
            over = ds["pressure_pa"][:] > ds.active_threshold_pa
            kinds = np.array([json.loads(c)["kind"] for c in ds["contactor"][:]])
            force = ds["force_n"][:]
        for kind in ("hand", "object", "body"):
            if not (kinds == kind).any():
                continue
            mean, low, high = row["prints"][f"{kind}.active"]
            assert mean == pytest.approx(over[kinds == kind].sum(axis=1).mean())
            assert low <= mean <= high
            assert row["prints"][f"{kind}.force_n"][0] == pytest.approx(
                force[kinds == kind].mean(), rel=1e-6
            )


def test_rule_against_brute_force_on_random_inputs():
    rng = np.random.default_rng(0)
    for _ in range(200):
        n = int(rng.integers(1, 7))
        speeds = [None if rng.random() < 0.2 else float(rng.uniform(1, 50)) for _ in range(n)]
        accs = [
            None if rng.random() < 0.2 else float(rng.choice([60.0, 80.0, 90.5, 91.0]))
            for _ in range(n)
        ]
        n_test = int(rng.integers(10, 2000))
        same = [bool(rng.random() < 0.7) for _ in range(n)]
        got = F.choose_default(speeds, accs, n_test, same)
        known = [i for i in range(n) if speeds[i] is not None and accs[i] is not None]
        if not known:
            assert got is None
            continue
        top = max(accs[i] for i in known)
        tol = F.tolerance_pt(top, n_test)
        fine = [i for i in known if accs[i] >= top - tol]
        fine = [i for i in fine if same[i]] or fine
        assert accs[got.index] >= top - tol
        assert speeds[got.index] == max(speeds[i] for i in fine)


def test_rerun_reuses_data_and_models_and_gives_the_same_results(run, capsys):
    out, results = run
    again = run_fidelity(out, PLAN, settings=SETTINGS, base=tiny_base(), progress=False)
    assert json.dumps(again, sort_keys=True) == json.dumps(results, sort_keys=True)
    printed = capsys.readouterr().out
    assert printed.count("reusing") == 2 * len(SETTINGS) + 1  # datasets (+ rich), models


def test_a_dataset_without_recorded_speed_is_reused_as_unknown(run, tmp_path):
    """Without its timing file a complete dataset is not regenerated: its speed is unknown,
    shown as such, and the rule skips it."""
    out, results = run
    first = _rows(results)["cheapest"]
    timing = Path(first["dataset"] + ".timing.json")
    saved = timing.read_text()
    timing.unlink()
    shutil.copytree(out / "models", tmp_path / "o" / "models")  # reused: no training
    try:
        again = run_fidelity(
            tmp_path / "o",
            PLAN,
            datasets=out / "data",
            settings=SETTINGS,
            base=tiny_base(),
            progress=False,
        )
    finally:
        timing.write_text(saved)
    row = _rows(again)["cheapest"]
    assert row["per_core"] is None and row["n_computed"] == 0
    assert row["accuracy_pct"] == first["accuracy_pct"]
    assert "| `cheapest` |" in (text := (tmp_path / "o" / "report.md").read_text())
    assert "unknown" in text.split("| `cheapest` |")[1].split("\n")[0]
    assert again["choice"]["name"] != "cheapest"


def test_segnet_option_reports_a_mean_iou_that_pixel_counts_reproduce(run, tmp_path, near_ties):
    import torch

    from learn.inputs import net_input
    from learn.train.checkpoint import LAST, load_checkpoint, model_from_checkpoint
    from tactile.dataset.reader import open_dataset
    from tactile.images.resize import resize_labels

    out, results = run
    shutil.copytree(out / "models", tmp_path / "o" / "models")  # HandsNet reused
    res = run_fidelity(
        tmp_path / "o",
        dataclasses.replace(PLAN, segmentation=True),
        datasets=out / "data",
        settings=["default"],
        base=tiny_base(),
        progress=False,
    )
    (ckpt,) = (tmp_path / "o" / "models").glob(f"segnet-default-*/{LAST}")
    model = model_from_checkpoint(load_checkpoint(ckpt))[0]
    size = PLAN.image_px
    with open_dataset(results["test_set"]["dataset"]) as ds:
        test = ds.splits["test"]
        x = net_input(ds.image[np.sort(test)], size, "segment")[np.argsort(np.argsort(test))]
        truth = np.stack([resize_labels(ds.label_image[i], size) for i in test])
    with torch.no_grad():
        scores = model(torch.from_numpy(x)[:, None]).numpy()
    pred = np.where(x > 0, scores.argmax(1), 0)  # unpressed pixels are background (learn.inputs)
    unions = [np.sum((pred == c) | (truth == c)) for c in range(7) if np.any(truth == c)]
    ious = [
        np.sum((pred == c) & (truth == c)) / np.sum((pred == c) | (truth == c))
        for c in range(7)
        if np.any(truth == c)
    ]
    # k decisions made the other way move each IoU by at most 2k / (its union - k)
    k = near_ties.count(np.where(x[:, None] > 0, scores, np.eye(7)[0][:, None, None]))
    tolerance = 100 * 2 * k / (min(unions) - k) if k else 1e-9
    assert abs(res["settings"][0]["miou_pct"] - 100 * np.mean(ious)) <= tolerance
    assert (tmp_path / "o" / "speed_miou.png").is_file()
    assert "SegNet mIoU %" in (tmp_path / "o" / "report.md").read_text()


@pytest.mark.parametrize(
    "change",
    [
        {"settings": ["default", "bogus"]},
        {"n": 3},
        {"epochs": 0},
        {"image_px": (16, 48)},
        {"workers": 0},
        {"seed": -1},
    ],
)
def test_bad_input_fails_before_any_work(tmp_path, change):
    settings = change.pop("settings", SETTINGS)
    with pytest.raises(ConfigError):
        plan = dataclasses.replace(PLAN, **change)
        run_fidelity(tmp_path / "out", plan, settings=settings, base=tiny_base(), progress=False)
    assert not (tmp_path / "out").exists()


def test_cli_reports_a_bad_setting_with_exit_code_2(tmp_path):
    from typer.testing import CliRunner

    from handskin.cli import app

    res = CliRunner().invoke(
        app, ["experiment", "fidelity", "--out", str(tmp_path / "o"), "--settings", "default,nope"]
    )
    assert res.exit_code == 2 and "nope" in res.output and "choose among" in res.output
    assert not (tmp_path / "o").exists()


def test_a_setting_that_fails_is_reported_and_never_chosen(run, tmp_path):
    """A setting whose generation gave up on a sample (`sim.episode.runner.SampleFailed`) keeps
    its row, with no speed, score or prints: the report names it and why, the table says it
    fails, the rule and the prints' table pass over it."""
    from experiments.fidelity import UNMEASURED, probe_run
    from experiments.report import Report

    _, results = run
    chosen = results["choice"]["name"]
    chosen = chosen if chosen != "default" else "cheapest"  # the default's prints stay known
    why = "sample 3 (seed 5) failed 20 attempts: {'warning': 20}"
    rows = [
        r | dict.fromkeys(UNMEASURED) | {"failed": why} if r["name"] == chosen else r
        for r in results["settings"]
    ]
    rep = Report("fidelity", tmp_path, seed=PLAN.seed, config={})
    probe = probe_run("handsnet", PLAN).train
    again = F.write_report(rep, rows, PLAN, probe, "plate", results["test_set"])
    text = (tmp_path / "report.md").read_text()
    assert f"- `{chosen}` (" in text and why in text and "## Settings that fail" in text
    line = next(t for t in text.splitlines() if t.startswith(f"| `{chosen}` |"))
    assert "fails" in line
    assert again["choice"]["name"] != chosen
    prints = text[text.index("## Prints") : text.index("## Settings that fail")]
    assert f"`{chosen}`" not in prints
