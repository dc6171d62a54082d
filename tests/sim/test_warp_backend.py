"""`handskin generate --backend warp`: refusals before work, batched models equal to each world's
own conversion, worlds independent of their batch (bit for bit on warp's CPU device), the same
bytes for any --worlds and --workers, and data statistically equivalent to the C backend's on the
same seeds.

The stepping tests compile MJWarp's kernels on first use (about a minute on 2 cores, cached in
~/.cache/warp afterwards) and simulate on warp's CPU device: they are marked slow.
"""

from __future__ import annotations

import hashlib
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

pytest.importorskip("mujoco_warp", reason="the warp extra is not installed")

from handskin.cli import app
from sim.contactors.spec import sphere_contactor
from sim.episode.runner import episode_rng
from sim.generate.config import MixConfig, load_generate_config
from sim.generate.run import generate
from sim.generate.sampler import build_state, is_hand_index, maker_at
from sim.warp.options import WarpOptions, check_warp
from tactile.dataset import open_dataset
from tactile.dataset.manifest import claim_folder, make_manifest
from tactile.errors import ConfigError, DataError
from tactile.prints.measures import bootstrap_mean, read_prints

check_warp(WarpOptions())  # quiet warp before the modules below start it

from sim.warp import backend as warp_backend  # noqa: E402
from sim.warp.batch import run_batch  # noqa: E402
from sim.warp.jobs import JobMaker  # noqa: E402
from sim.warp.model import BATCHABLE, batch_models, convert, structure_digest  # noqa: E402
from sim.warp.run import generate as warp_generate  # noqa: E402

# The CI scale of tests/sim/test_generate.py: 12 plate samples, short presses.
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


def small(**kw: object):
    return load_generate_config(None, **(SMALL | kw))


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def state():
    return build_state(small())


def hand_jobs(state, indices, maker: JobMaker, aim_seed: int | None = None):
    """(job, key model, C-scene conversion right after its reset) of sample i's attempt 0;
    with ``aim_seed``, pressed at a site drawn from that seed instead of the plan's."""
    out = []
    for i in indices:
        rng, _ = episode_rng(state.cfg.seed, i, 0)
        contactor, plan = maker_at(i, state)(rng)
        if aim_seed is not None:
            plan, rng = replace(plan, site_uv=None), np.random.default_rng(aim_seed)
        job, km = maker.prepare(contactor, plan, rng)
        out.append((job, km, convert(job.scene.model, "cpu")))
    return out


HANDS = [i for i in range(40) if is_hand_index(i, small().hand_fraction)][:4]


def test_options_are_checked_before_any_work(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"--worlds 0 is out of range"):
        WarpOptions(worlds=0)
    with pytest.raises(ConfigError, match=r"--device 'gpu' unknown; give cpu, cuda or cuda:N"):
        WarpOptions(device="gpu")
    with pytest.raises(ConfigError, match=r"--njmax 0 is out of range"):
        WarpOptions(njmax=0)
    with pytest.raises(ConfigError, match=r"--device cuda:7 is not available; warp sees cpu"):
        check_warp(WarpOptions(device="cuda:7"))
    with pytest.raises(ConfigError, match=r"need --backend warp"):
        warp_generate(small(), tmp_path / "a", warp=WarpOptions(), progress=False)
    with pytest.raises(ConfigError, match=r"--ray runs the C backend only"):
        generate(small(backend="warp"), tmp_path / "b", ray="local", progress=False)
    with pytest.raises(ConfigError, match=r"backend = 'warp' runs through sim.warp.run.generate"):
        generate(small(backend="warp"), tmp_path / "b", progress=False)
    with pytest.raises(ConfigError, match=r"backend = 'jax' unknown; choose one of mujoco, warp"):
        small(backend="jax")
    mixed = replace(small(backend="warp", split="keyed"), mix=MixConfig(fraction=0.5))
    with pytest.raises(ConfigError, match=r"\[mix\] fraction > 0 .* runs on the C backend only"):
        warp_generate(mixed, tmp_path / "c", progress=False)
    assert not any((tmp_path / x).exists() for x in "abc")


def test_a_missing_package_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "mujoco_warp", None)  # import fails as if not installed
    with pytest.raises(ConfigError, match=r"pip install 'handskin\[warp\]'"):
        check_warp(WarpOptions())


def test_a_mismatched_pair_names_both_versions_and_the_fix(monkeypatch: pytest.MonkeyPatch):
    from importlib import metadata

    real = metadata.version
    monkeypatch.setattr(
        metadata, "version", lambda name: "3.9.9" if name == "mujoco-warp" else real(name)
    )
    mujoco_version = real("mujoco")
    with pytest.raises(
        ConfigError,
        match=rf"mujoco-warp 3\.9\.9 does not match mujoco {mujoco_version}.*pip install "
        r"'handskin\[warp\]' \(it pins a pair\), or pip install 'mujoco==3\.9\.9' "
        r"'mujoco-warp==3\.9\.9'",
    ):
        check_warp(WarpOptions())


def test_the_warp_extra_pins_the_pair_the_backend_needs() -> None:
    """The installed pair agrees, and the extra pins mujoco and mujoco-warp to one version."""
    from importlib import metadata

    from tactile.config import tomllib

    extra = tomllib.loads((Path(__file__).parents[2] / "pyproject.toml").read_text())
    pins = dict(
        r.split("==") for r in extra["project"]["optional-dependencies"]["warp"] if "==" in r
    )
    assert set(pins) == {"mujoco", "mujoco-warp"} and len(set(pins.values())) == 1, pins
    assert metadata.version("mujoco-warp") == metadata.version("mujoco")


def test_the_cli_names_the_flag(tmp_path: Path) -> None:
    out = tmp_path / "ds"
    args = ["generate", "--out", str(out), "--backend", "warp", "--worlds", "0"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2 and "error: --worlds 0 is out of range" in result.output
    result = CliRunner().invoke(app, ["generate", "--out", str(out), "--backend", "jax"])
    assert result.exit_code == 2 and "error: --backend jax unknown" in result.output
    assert not out.exists()


@pytest.mark.parametrize(("first", "second"), [("mujoco", "warp"), ("warp", "mujoco")])
def test_a_folder_of_one_backend_is_never_resumed_by_the_other(tmp_path, first, second) -> None:
    cfg = small(backend=first)
    claim_folder(tmp_path, make_manifest(cfg, cfg.part_id(), "v", cfg.seed))
    before = sorted(p.name for p in tmp_path.iterdir())
    with pytest.raises(DataError, match=rf"generated with --backend {first}.*never mixed"):
        run = warp_generate if second == "warp" else generate
        run(small(backend=second), tmp_path, workers=1, progress=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_a_batched_model_gives_each_world_its_own_conversion(state) -> None:
    """Every hand (other subjects, both sides) is one family; the batched model's world w holds
    exactly what put_model makes of w's scene after its reset (the contactor's rows kept per
    key, the reset's pose as the job's own), and a sphere is another family."""
    sides = {maker_at(i, state)(episode_rng(state.cfg.seed, i, 0)[0])[0].name for i in HANDS}
    assert sides == {"left_hand", "right_hand"}
    maker = JobMaker(state.ctx, "cpu")
    jobs = hand_jobs(state, HANDS, maker)
    jobs += hand_jobs(state, HANDS[:1], maker, aim_seed=1)  # same hand, another press pose
    assert not np.array_equal(jobs[0][0].rows["body_pos"], jobs[-1][0].rows["body_pos"])
    assert len({km.digest for _, km, _ in jobs}) == 1
    assert len({id(j.model) for j, _, _ in jobs}) == 1  # the family's one device model
    batched = batch_models(jobs[0][0].model, [j.rows for j, _, _ in jobs], "cpu")
    for name in sorted(BATCHABLE):
        rows = getattr(batched, name)
        if rows is None:
            continue
        rows = rows.numpy()
        for w, (_, _, own) in enumerate(jobs):
            np.testing.assert_array_equal(rows[w % len(rows)], getattr(own, name).numpy()[0], name)
    sphere = state.ctx.scene(sphere_contactor()).model
    assert structure_digest(sphere, convert(sphere, "cpu")) != jobs[0][1].digest


def test_a_single_window_runs_in_this_process(state, monkeypatch: pytest.MonkeyPatch) -> None:
    """--workers 2 with one window of chunks computes it here (a pool of one is not started)."""
    calls = []
    monkeypatch.setattr(warp_backend, "make_window", lambda w, o, note=None: calls.append(w) or [])
    opts = WarpOptions(worlds=8)
    assert list(warp_backend.warp_chunk_results(state.cfg, state.ctx, [0, 1], 2, opts)) == []
    assert calls == [[0, 1]] and warp_backend.window_chunks(state.cfg, opts) >= 2


def _frames(outcome) -> list[tuple]:
    return [(f.depth_m, f.pressure_pa, f.force_n, f.sensed_force_n, f.geom) for f in outcome.frames]


@pytest.mark.slow
def test_a_world_does_not_depend_on_its_batch(state) -> None:
    """The same episode alone, first or last among others, with more room: the same bits."""
    maker = JobMaker(state.ctx, "cpu")
    jobs = [j for j, _, _ in hand_jobs(state, HANDS[:3], maker)]
    ctx = state.ctx
    args = (ctx.skin, ctx.cfg.active_pa, "cpu")
    together = run_batch(jobs, *args, 128, 512)
    reordered = run_batch(jobs[::-1], *args, 64, 256)[::-1]
    alone = [run_batch([j], *args, 256, 1024)[0] for j in jobs]
    for outcomes in (reordered, alone):
        for a, b in zip(together, outcomes, strict=True):
            assert type(a) is type(b)
            for fa, fb in zip(_frames(a), _frames(b), strict=True):
                for x, y in zip(fa, fb, strict=True):
                    np.testing.assert_array_equal(x, y)
    assert any(o.best_active for o in together)  # the hands did press the plate


@pytest.fixture(scope="module")
def warp_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("warp") / "ds"
    warp_generate(small(backend="warp"), out, workers=1, progress=False, warp=WarpOptions(worlds=8))
    return out


@pytest.fixture(scope="module")
def c_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("c") / "ds"
    generate(small(), out, workers=1, progress=False)
    return out


@pytest.mark.slow
def test_same_bytes_for_any_worlds_and_workers(warp_run: Path, tmp_path: Path) -> None:
    opts = WarpOptions(worlds=2, nconmax=96, njmax=320)
    warp_generate(small(backend="warp"), tmp_path / "w", workers=2, progress=False, warp=opts)
    assert sha256(tmp_path / "w" / "dataset.h5") == sha256(warp_run / "dataset.h5")


@pytest.mark.slow
def test_the_backends_agree_on_the_same_seeds(warp_run: Path, c_run: Path) -> None:
    """Same samples, labels and split structure; the prints agree within tolerances set by the
    physics' differences (float32, MJWarp's convex collision): active taxels and force within
    10 % of the C backend's mean, parts per hand within 0.5."""
    with open_dataset(c_run) as c, open_dataset(warp_run) as w:
        assert len(c) == len(w) == 12 and c.fields == w.fields
        for name in ("is_hand", "action", "subject_id", "instance_id", "episode_seed"):
            np.testing.assert_array_equal(c[name][()], w[name][()])
        for name in ("taxel_label", "label_image"):
            assert set(np.unique(w[name][()])) <= set(range(7))
        assert len(c.splits["test"]) == len(w.splits["test"])
        assert w.attrs["config"]["backend"] == "warp" and "device cpu" in w.attrs["simulator"]
        pc, pw = read_prints(c), read_prints(w)
    mean = lambda v: bootstrap_mean(v)[0]  # noqa: E731
    print(f"\nC / warp: active {mean(pc.active):.1f} / {mean(pw.active):.1f}, force N ", end="")
    print(f"{mean(pc.force_n):.2f} / {mean(pw.force_n):.2f}")
    assert abs(mean(pw.active) - mean(pc.active)) <= 0.1 * mean(pc.active)
    assert abs(mean(pw.force_n) - mean(pc.force_n)) <= 0.1 * mean(pc.force_n)
    hands_c, hands_w = pc.parts[pc.kind == "hand"], pw.parts[pw.kind == "hand"]
    assert abs(hands_w.mean() - hands_c.mean()) <= 0.5
