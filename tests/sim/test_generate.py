"""`handskin generate`: same bytes for any worker count, resume after SIGKILL, refusals before work,
shards merged equal a single run, configuration errors naming field and range; Ray if installed."""

from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from sim.generate import sampler
from sim.generate.config import GenerateConfig, load_generate_config
from sim.generate.run import generate
from sim.generate.sampler import is_hand_index
from sim.generate.shards import merge_shards, parse_shard, shard_chunks
from tactile.config import to_toml
from tactile.dataset import list_chunks, open_dataset
from tactile.dataset.readout import NOISE_FLOOR_SIGMAS
from tactile.errors import ConfigError, DataError

ROOT = Path(__file__).resolve().parents[2]
# 12 plate samples in 4 chunks of 3, short presses: about a second of simulation per run. A
# hand is sometimes too big for the small plate: more attempts than the default keep it robust.
SMALL = {
    "part": "plate",
    "n": 12,
    "chunk_size": 3,
    "n_subjects": 3,
    "instances_per_kind": 2,
    "duration_scale": 0.5,
    "seed": 5,
    "episode": {"max_attempts": 20},
}


def small(**kw: object) -> GenerateConfig:
    return load_generate_config(None, **(SMALL | kw))


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An uninterrupted in-process run (one worker) of the small configuration."""
    out = tmp_path_factory.mktemp("ref") / "ds"
    report = generate(small(), out, workers=1, progress=False)
    assert report.dataset == out / "dataset.h5" and report.n_computed == 12
    return out


def test_two_workers_give_the_same_bytes_as_one(reference: Path, tmp_path: Path) -> None:
    generate(small(), tmp_path / "w2", workers=2, progress=False)
    assert sha256(tmp_path / "w2" / "dataset.h5") == sha256(reference / "dataset.h5")


def test_images_regenerated_from_raw_readings_equal_the_stored_ones(reference: Path) -> None:
    """The reference is the generator's own images: raw counts, the frame times and the stored
    skin attrs (baseline, drift, noise floor, gain) must give them back bit for bit."""
    with open_dataset(reference) as ds:
        attrs = ds.attrs
        assert np.abs(attrs["skin_drift_counts_per_s"]).max() > 0  # drift really is removed
        noise_std = small().episode.skin.noise_std_counts
        assert attrs["skin_noise_floor_counts"] == NOISE_FLOOR_SIGMAS * noise_std
        raw, t, stored = ds.raw[:], ds.time_s[:], ds.image[:]
        np.testing.assert_array_equal(ds.images_from_raw(raw, time_s=t), stored)
        untouched = ds.pressure_from_raw(np.rint(attrs["skin_baseline_counts"]).astype(np.uint16))
        assert not untouched.any()  # the bare noise-free baseline reads 0 Pa


def test_dataset_content_classes_subjects_and_split(reference: Path) -> None:
    with open_dataset(reference) as ds:
        is_hand = ds["is_hand"][()]
        want = [is_hand_index(i, small().hand_fraction) for i in range(12)]
        np.testing.assert_array_equal(is_hand, want)
        assert set(ds["subject_id"][()][is_hand == 1]) <= {0, 1, 2}
        train, test = ds.splits["train"], ds.splits["test"]
        assert len(train) + len(test) == 12
        subj = ds["subject_id"][()]
        assert not set(subj[train][subj[train] >= 0]) & set(subj[test][subj[test] >= 0])
        assert ds.attrs["config"]["n"] == 12 and ds.attrs["seed"] == 5
        assert ds.attrs["versions"]["mujoco"] and ds.attrs["generator_version"]


def test_keyed_split_holds_out_the_same_people_at_any_n(tmp_path: Path, keyed_reference) -> None:
    """--split keyed: each dataset's sides are the documented draws (tactile.dataset.splits),
    and a dataset twice the size (more samples per subject and instance, more instances) keeps
    every shared subject and instance on its side unless the small one needed the both-sides
    exception."""
    reference, sides_of = keyed_reference
    sides = []
    for n in (12, 24):
        generate(small(split="keyed", n=n), tmp_path / f"n{n}", workers=1, progress=False)
        with open_dataset(tmp_path / f"n{n}") as ds:
            assert ds.attrs["split_method"] == "keyed"
            sides.append(sides_of(ds["subject_id"][()], ds["instance_id"][()], ds.splits["train"]))
        assert sides[-1] == reference(set(sides[-1]), SMALL["seed"])
    common = sides[0].keys() & sides[1].keys()
    moved = [k for k in common if sides[0][k] != sides[1][k]]
    assert len(common) >= 6 and len(moved) <= 1  # seed 5: n = 12 puts all instances in train


def test_sigkill_mid_run_then_resume_equals_uninterrupted(reference: Path, tmp_path: Path) -> None:
    out = tmp_path / "killed"
    cfg_file = tmp_path / "small.toml"
    cfg_file.write_text(to_toml(small()))  # the CLI options below repeat some of its values
    argv = [
        sys.executable,
        "-c",  # the generate command as `handskin generate` registers it
        "import typer; from sim.cli.parts import register; "
        "app = typer.Typer(); register(app); app()",
        "generate",
        "--out",
        str(out),
        "--workers",
        "1",
        "--no-progress",
        "--config",
        str(cfg_file),
        *[f"--{k.replace('_', '-')}={v}" for k, v in SMALL.items() if k in CLI],
    ]
    log = tmp_path / "stderr.txt"
    with log.open("w") as err:
        proc = subprocess.Popen(argv, cwd=ROOT, env=_env(), stderr=err)
    try:
        _wait_for(lambda: len(list_chunks(out)) >= 1, proc, timeout_s=60, log=log)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    assert 1 <= len(list_chunks(out)) < 4 and not (out / "dataset.h5").exists()
    done = subprocess.run(argv, cwd=ROOT, env=_env(), check=True, capture_output=True, text=True)
    assert sha256(out / "dataset.h5") == sha256(reference / "dataset.h5")
    with open_dataset(reference) as ds:  # the closing line says how the dataset was split
        train, test = ds.splits["train"], ds.splits["test"]
        held = len(set(ds["subject_id"][()][test].tolist()) - {-1})
    assert (
        f"split (greedy): {len(train)} train / {len(test)} test samples "
        f"({100 * len(train) / 12:.1f} % train); held out: {held} subjects"
    ) in done.stdout


CLI = ("part", "n", "seed", "chunk_size")


def _env() -> dict[str, str]:
    return dict(os.environ, PYTHONPATH=str(ROOT))


def _wait_for(cond, proc: subprocess.Popen, timeout_s: float, log: Path) -> None:
    end = time.monotonic() + timeout_s
    while not cond():
        assert proc.poll() is None, f"the generator ended before the kill: {log.read_text()}"
        assert time.monotonic() < end, "no chunk written in time"
        time.sleep(0.01)  # a chunk takes >= 0.1 s: the kill lands before the next one


def test_folder_of_another_configuration_is_refused_untouched(
    reference: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Refused before any sample is simulated (the in-process runner would be called first),
    and nothing in the folder is touched."""

    def no_sampling(*args: object, **kw: object) -> None:
        raise AssertionError("a sample was simulated before the refusal")

    monkeypatch.setattr(sampler, "run_sample", no_sampling)
    before = {p: p.stat().st_mtime_ns for p in reference.rglob("*")}
    with pytest.raises(DataError, match=r"another configuration.*seed"):
        generate(small(seed=6), reference, workers=1, progress=False)
    assert {p: p.stat().st_mtime_ns for p in reference.rglob("*")} == before


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"n": -5}, r"n = -5 is out of range; allowed \[1, 100000000\]"),
        ({"hand_fraction": 1.5}, r"hand_fraction = 1.5 is out of range; allowed \[0, 1\]"),
        ({"part": "foream"}, r"unknown part 'foream'; known parts: forearm.*link mesh file"),
        ({"chunk_size": 0}, r"chunk_size = 0 is out of range"),
        ({"episode": {"solver_iterations": 0}}, r"episode.solver_iterations = 0 is out of range"),
        ({"hand_detail": "fine"}, r"hand_detail = 'fine' unknown; choose one of full, coarse"),
        ({"split": "random"}, r"split = 'random' unknown; choose one of greedy, keyed"),
    ],
)
def test_bad_values_fail_naming_field_and_range(changes: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        small(**changes)


def test_bad_config_files_fail_before_any_work(tmp_path: Path) -> None:
    bad = {
        "unknown key": ("n_subject = 5\n", r"unknown key 'n_subject'.*known keys:.*n_subjects"),
        "nested range": ("[episode]\ntimestep_s = 0.5\n", r"episode.timestep_s = 0.5 is out of"),
        "skin": ("[episode.skin]\nnoise_std_counts = -1.0\n", r"noise_std_counts.*>= 0"),
        "type": ('n = "many"\n', r"n: expected int"),
    }
    for name, (text, message) in bad.items():
        path = tmp_path / f"{name}.toml"
        path.write_text(text)
        with pytest.raises(ConfigError, match=message):
            load_generate_config(path)
    assert not list(tmp_path.glob("*/chunks"))


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--n", "-3"], "--n -3 is out of range; allowed [1, 100000000]"),
        (["--hand-fraction", "1.5"], "--hand-fraction 1.5 is out of range; allowed [0, 1]"),
        (["--split", "random"], "--split random unknown; choose one of greedy, keyed"),
        (["--chunk-size", "0"], "--chunk-size 0 is out of range"),
        (["--part", "plate", "--workers", "0"], "--workers 0 is out of range; allowed >= 1"),
        (["--shard", "2/2"], "--shard '2/2': need 0 <= i < n"),
    ],
)
def test_cli_reports_bad_input_naming_the_flag(tmp_path: Path, flags: list[str], message: str):
    """Exit code 2, the flag as typed in the message, nothing written."""
    import typer
    from typer.testing import CliRunner

    from sim.cli.parts import register

    app = typer.Typer()
    register(app)
    out = tmp_path / "never"
    result = CliRunner().invoke(app, ["generate", "--out", str(out), *flags])
    assert result.exit_code == 2 and message in " ".join(result.output.split()), result.output
    assert not out.exists()


def test_shards_merged_equal_a_single_run(reference: Path, tmp_path: Path) -> None:
    assert parse_shard("1/3") == (1, 3) and shard_chunks(4, (1, 3)) == [1]
    shards = [tmp_path / f"shard{i}" for i in range(2)]
    for i, folder in enumerate(shards):
        report = generate(small(), folder, workers=1, shard=(i, 2), progress=False)
        assert report.dataset is None and list_chunks(folder) == [i, i + 2]
    merged = merge_shards(shards, tmp_path / "merged")
    assert sha256(merged) == sha256(reference / "dataset.h5")
    generate(small(seed=9), tmp_path / "other", workers=1, shard=(0, 2), progress=False)
    with pytest.raises(DataError, match="another dataset"):
        merge_shards([shards[0], tmp_path / "other"], tmp_path / "mixed")


def test_ray_run_gives_the_same_bytes(reference: Path, tmp_path: Path) -> None:
    pytest.importorskip("ray", reason="the ray extra is not installed")
    generate(small(), tmp_path / "ray", workers=2, ray="local", progress=False)
    assert sha256(tmp_path / "ray" / "dataset.h5") == sha256(reference / "dataset.h5")


def test_contact_sheet_of_the_generated_dataset(reference: Path, tmp_path: Path) -> None:
    from tactile.cli.dataset import select_samples, write_sheet

    png = write_sheet(reference, tmp_path / "hands.png", n=4, cls="hand")
    assert png.stat().st_size > 1000
    with open_dataset(reference) as ds:
        picked = select_samples(ds, cls="non_hand", n=3)
        assert len(picked) == 3 and not ds["is_hand"][()][picked].any()
        with pytest.raises(DataError, match="unknown; actions: grasp"):
            select_samples(ds, action="wave")


def test_folder_started_by_other_code_is_refused_with_the_reason(tmp_path: Path) -> None:
    from sim.generate.config import generator_version, refuse_other_code
    from tactile.dataset.manifest import make_manifest

    cfg = small()
    old = make_manifest(cfg, cfg.part_id(), "0.0.1+src.000000000000", cfg.seed)
    (tmp_path / "manifest.json").write_text(json.dumps(old))
    with pytest.raises(DataError, match="started by other generator code"):
        refuse_other_code(tmp_path, make_manifest(cfg, "plate", generator_version(), cfg.seed))


def test_generator_version_hashes_the_sim_and_tactile_sources() -> None:
    """The version in every fingerprint covers the code that made the data: an independent hash
    of the sim/ and tactile/ package sources as installed (not the hash of no files)."""
    import hashlib

    import sim
    import tactile
    from sim.generate.config import generator_version

    digest = hashlib.sha256()
    files = []
    for package in (sim, tactile):
        top = Path(package.__file__).parent
        files += [(p.relative_to(top.parent).as_posix(), p) for p in top.rglob("*.py")]
    for name, path in sorted(files):
        digest.update(name.encode() + b"\0" + path.read_bytes())
    assert len(files) > 50
    assert generator_version().endswith("+src." + digest.hexdigest()[:12])
    assert not generator_version().endswith(hashlib.sha256().hexdigest()[:12])


def test_min_active_taxels_replaces_only_the_small_prints(reference: Path, tmp_path: Path) -> None:
    """A sample of the unfiltered run with >= M active taxels passed every check the filtered run
    makes at the same attempt, so it is kept byte for byte; the others are redrawn to >= M."""
    ref = open_dataset(reference)
    threshold = ref.attrs["config"]["episode"]["active_pa"]
    active = (ref.pressure_pa[:] > threshold).sum(axis=1)
    m = int(np.median(active))  # about half the prints are below it
    assert 1 < m and (active < m).any()
    out = tmp_path / "ds"
    generate(
        small(episode={"max_attempts": 40, "min_active_taxels": m}), out, workers=1, progress=False
    )
    ds = open_dataset(out)
    assert ((ds.pressure_pa[:] > threshold).sum(axis=1) >= m).all()
    raw_ref, raw = ref.raw[:], ds.raw[:]
    for i in range(len(active)):
        same = np.array_equal(raw_ref[i], raw[i])
        assert same == (active[i] >= m), f"sample {i}: {active[i]} active taxels, m = {m}"
    assert ds.attrs["rejects"]["few_taxels"] >= int((active < m).sum())


def test_min_active_taxels_out_of_range_is_refused() -> None:
    with pytest.raises(ConfigError, match=r"episode.min_active_taxels = 0 is out of range"):
        small(episode={"min_active_taxels": 0})
    with pytest.raises(ConfigError, match=r"min_active_taxels: expected int"):
        small(episode={"min_active_taxels": 2.5})


@pytest.mark.parametrize("name", ["generate_example", "generate_diverse", "generate_min_taxels"])
def test_the_documented_configuration_files_load(name: str) -> None:
    cfg = load_generate_config(ROOT / "docs" / f"{name}.toml")
    if name == "generate_min_taxels":
        assert (cfg.episode.min_active_taxels, cfg.episode.max_attempts) == (20, 40)


def test_a_size_floor_above_the_part_s_taxel_count_is_refused_before_any_work(tmp_path):
    from sim.skin.parts import get_part

    n_taxels = len(get_part("plate").layout.positions_m)
    out = tmp_path / "ds"
    with pytest.raises(
        ConfigError,
        match=rf"min_active_taxels = {n_taxels + 1} is more than "
        rf"the {n_taxels} taxels of part 'plate'",
    ):
        generate(small(episode={"min_active_taxels": n_taxels + 1}), out, workers=1, progress=False)
    assert not out.exists()
