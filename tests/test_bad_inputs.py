"""Bad input across every subcommand, as a new user types it: each is refused with exit status 2
and the words that name the problem and the fix, without a Python traceback, with every file that
existed before unchanged and no temporary file left. A read-only disk is simulated by the check
that sees it (`tactile.files._read_only`), a full disk by writes that raise ENOSPC once a byte
budget is spent (every file opened for writing, or torch.save)."""

from __future__ import annotations

import builtins
import errno
import hashlib
import io
import json
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import trimesh
from typer.testing import CliRunner

from handskin.cli import app
from tactile import files
from tactile.geometry.synthetic import cylinder_sector_layout

runner = CliRunner()
SMALL = """part = "plate"\nn = 12\nchunk_size = 3\nn_subjects = 3\ninstances_per_kind = 2
duration_scale = 0.5\nseed = 5\n[episode]\nmax_attempts = 20\n"""
RUN = "threads = 1\n[model]\ninput_size = [32, 48]\n[train]\nepochs = 1\nbatch_size = 4\n"


def invoke(*args: object):
    return runner.invoke(app, [str(a) for a in args])


def flip_byte(path: Path, dataset: str, sample: int) -> None:
    """Flip one byte inside HDF5 chunk ``sample`` of ``dataset`` in ``path``."""
    import h5py

    with h5py.File(path, "r") as f:
        info = f[dataset].id.get_chunk_info_by_coord((sample,) + (0,) * (f[dataset].ndim - 1))
    data = bytearray(path.read_bytes())
    data[info.byte_offset + info.size // 2] ^= 0xFF
    path.write_bytes(bytes(data))


@pytest.fixture(scope="module")
def world(tmp_path_factory) -> dict[str, Path]:
    """Inputs good and bad, built once: a generated dataset (12 plate samples) and one of another
    seed, a damaged copy, an ingested recording with labels, a one-class recording, layouts,
    meshes, a trained checkpoint, run folders, an export."""
    root = tmp_path_factory.mktemp("bad_inputs")
    w = {"root": root, "ro": root / "ro", "new": root / "new", "nonempty": root / "nonempty"}
    w["ro"].mkdir()
    w["nonempty"].mkdir()
    (w["nonempty"] / "mine.txt").write_text("keep me\n")
    (root / "small.toml").write_text(SMALL)
    (root / "run.toml").write_text(RUN)
    for name, seed in (("ds", 5), ("other", 6)):
        config = ("--config", root / "small.toml", "--seed", seed, "--workers", 1)
        res = invoke("generate", "--out", root / name, *config, "--no-progress")
        assert res.exit_code == 0, res.output
        w[name] = root / name
    w["bad"] = root / "bad"
    shutil.copytree(w["ds"], w["bad"], ignore=shutil.ignore_patterns("chunks"))
    flip_byte(w["bad"] / "dataset.h5", "samples/image", 5)
    _layouts_and_recordings(root, w)
    _meshes(root, w)
    res = invoke("train", w["ds"], "--out", root / "run", "--config", root / "run.toml")
    assert res.exit_code == 0, res.output
    w["run"], w["ckpt"] = root / "run", root / "run" / "best.pt"
    w["best_only"] = root / "best_only"
    w["best_only"].mkdir()
    shutil.copy(w["ckpt"], w["best_only"] / "best.pt")
    res = invoke("export", w["ds"], "--out", root / "exp", "--no-progress")
    assert res.exit_code == 0, res.output
    w["exp"] = root / "exp"
    (root / "notes.png").write_text("not an image\n")
    (root / "text.jpg").write_text("not an image either\n")
    _frames_and_links(root, w)
    _edited_sidecars(root, w)
    _configs_and_surfaces(root)
    return w


def _configs_and_surfaces(root: Path) -> None:
    """A run TOML naming an arch, a generation no taxel can answer, a skin whose noise hides
    every press, taxels covering a sphere (a closed surface)."""
    (root / "vgg.toml").write_text(RUN.replace("[model]\n", '[model]\narch = "vgg16"\n'))
    deaf = SMALL.replace("max_attempts = 20", "max_attempts = 2\nactive_pa = 999999.0")
    (root / "deaf.toml").write_text(deaf)
    (root / "noisy.toml").write_text(SMALL + "[episode.skin]\nnoise_std_counts = 60000.0\n")
    sphere = trimesh.creation.icosphere(subdivisions=2, radius=0.05).vertices
    np.savetxt(root / "sphere.csv", sphere, delimiter=",", header="x_m,y_m,z_m", comments="")


def _edited_sidecars(root: Path, w: dict) -> None:
    """Copies of the dataset with a hand-edited info.json or manifest.json, and a run that was
    not merged, one of its chunks missing."""

    def manifest(edit):
        return lambda d: (d / "manifest.json").write_text(
            json.dumps(edit(json.loads((d / "manifest.json").read_text())))
        )

    edits = {
        "info_null": lambda d: (d / "info.json").write_text("null"),
        "info_list": lambda d: (d / "info.json").write_text("[1, 2]"),
        "sha_number": manifest(
            lambda m: m | {"content": {"dataset.h5": {"sha256": 1, "bytes": 2}}}
        ),
        "content_text": manifest(lambda m: m | {"content": "abc"}),
        "n_edited": manifest(lambda m: m | {"config": m["config"] | {"n": 40}}),
    }
    for name, edit in edits.items():
        shutil.copytree(w["ds"], root / name)
        edit(root / name)
    shutil.copytree(w["ds"], root / "unmerged")
    for name in ("dataset.h5", "info.json", "chunks/chunk_000001.h5"):
        (root / "unmerged" / name).unlink()


def _frames_and_links(root: Path, w: dict) -> None:
    """A link to the dataset's file, one sample's raw frame, frames of impossible counts."""
    import h5py

    (root / "link.png").symlink_to(w["ds"] / "dataset.h5")
    with h5py.File(w["ds"] / "dataset.h5") as f:
        raw = f["samples/raw"][0].astype(np.int64)
    np.save(root / "frame.npy", raw.astype(np.float64))
    np.savetxt(root / "frame_neg.csv", -raw[None] - 5, fmt="%d", delimiter=",")
    np.savetxt(root / "frame_big.csv", raw[None] + 70_000, fmt="%d", delimiter=",")
    np.save(root / "frame_1e300.npy", np.full(len(raw), 1e300))


def _layouts_and_recordings(root: Path, w: dict) -> None:
    layout, _ = cylinder_sector_layout(width_mm=60, length_mm=90, pitch_mm=8)
    layout.save(root / "layout.csv")
    layout.save(root / "layout.npz")
    rng = np.random.default_rng(0)
    (root / "binary.csv").write_bytes(rng.integers(0, 256, 4000, dtype=np.uint8).tobytes())
    (root / "binary.npz").write_bytes(rng.integers(0, 256, 4000, dtype=np.uint8).tobytes())
    (root / "huge.csv").write_text("x_m,y_m,z_m\n" + "0.1,0.2,0.3\n" * 2_000_000)
    frames = rng.integers(0, 900, (8, layout.n_taxels))
    np.savetxt(root / "frames.csv", frames, fmt="%d", delimiter=",")
    (root / "labels.csv").write_text("hand\nnon_hand\n" * 4)
    (root / "objects.csv").write_text("non_hand\n" * 8)
    for name, labels in (("ing", "labels.csv"), ("objects", "objects.csv")):
        inputs = (root / "layout.csv", root / "frames.csv", "--labels", root / labels)
        res = invoke("ingest", *inputs, "--out", root / name)
        assert res.exit_code == 0, res.output
        w[name] = root / name


def _meshes(root: Path, w: dict) -> None:
    tube = trimesh.creation.cylinder(radius=0.05, height=0.25, sections=48)
    mm = tube.copy()
    mm.apply_scale(1000.0)
    mm.export(root / "link_mm.stl")
    broken = trimesh.Trimesh(tube.vertices, np.vstack([tube.faces, tube.faces]), process=False)
    broken.export(root / "link_broken.stl")
    (root / "notamesh.stl").write_text("solid nothing\nendsolid nothing\n")


# ---- simulated disks --------------------------------------------------------------------------


def read_only(monkeypatch, w: dict) -> None:
    """The folder w["ro"] reads as a read-only disk."""
    real = files._read_only
    monkeypatch.setattr(files, "_read_only", lambda p: str(p).startswith(str(w["ro"])) or real(p))


class _Disk:
    def __init__(self, free: int) -> None:
        self.free = free


class _FullFile:
    """A file open for writing whose writes fail with ENOSPC once the disk's budget is spent."""

    def __init__(self, fh, disk: _Disk) -> None:
        self._fh, self._disk = fh, disk

    def write(self, data) -> int:
        n = len(data.encode()) if isinstance(data, str) else memoryview(data).nbytes
        if n > self._disk.free:
            raise OSError(errno.ENOSPC, "No space left on device")
        self._disk.free -= n
        return self._fh.write(data)

    def __getattr__(self, name):
        return getattr(self._fh, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self._fh.close()


def full_disk(free: int, only: str = ""):
    """A patch: files opened for writing (whose path holds ``only``) take ``free`` bytes in all,
    then raise ENOSPC; torch checkpoints fail after part of a file, as a full disk makes them."""

    def patch(monkeypatch, w: dict) -> None:
        disk, real_open = _Disk(free), builtins.open

        def fake_open(file, mode="r", *args, **kw):
            fh = real_open(file, mode, *args, **kw)
            hit = only in str(file) and any(c in mode for c in "wa+")
            return _FullFile(fh, disk) if hit else fh

        monkeypatch.setattr(builtins, "open", fake_open)
        monkeypatch.setattr(io, "open", fake_open)
        monkeypatch.setattr(files, "free_bytes", lambda path: 0)
        import torch

        def torch_save(obj, f, *args, **kw):
            Path(f).write_bytes(b"\0" * 1000)
            raise OSError(errno.ENOSPC, "No space left on device")

        monkeypatch.setattr(torch, "save", torch_save)

    return patch


# ---- the table --------------------------------------------------------------------------------


@dataclass(frozen=True)
class Case:
    id: str
    args: list[str]
    words: tuple[str, ...]
    patch: object = None
    writes: bool = False  # the command may leave complete new files (written before the fault)
    status: int = 2  # the exit status: 2, or the one the command documents (verify's fault: 1)


R = "{root}"
CASES = [
    # map: layout files and outputs
    Case("map-missing", ["map", R + "/nope.csv"], ("nope.csv", "no such layout file")),
    Case("map-binary", ["map", R + "/binary.csv"], ("binary.csv", "not a text", "binary")),
    Case("map-binary-npz", ["map", R + "/binary.npz"], ("binary.npz", "not a readable .npz")),
    Case("map-2M-taxels", ["map", R + "/huge.csv"], ("2,000,001 lines", "100,000 taxels")),
    Case("map-units", ["map", R + "/layout.csv", "--units", "km"], ("--units", "m or mm")),
    Case("map-npz-units", ["map", R + "/layout.npz", "--units", "mm"], ("leave out --units",)),
    Case("map-out-suffix", ["map", R + "/layout.csv", "--out", R + "/m.txt"], (".npz suffix",)),
    Case(
        "map-png-ro",
        ["map", R + "/layout.csv", "--png", R + "/ro/m.png"],
        ("--png", "read-only"),
        read_only,
    ),
    Case(
        "map-out-full",
        ["map", R + "/layout.csv", "--out", R + "/m.npz"],
        ("disk is full", "m.npz"),
        full_disk(0),
    ),
    # part and probe: meshes, views, outputs
    Case("part-mm-mesh", ["part", "--mesh", R + "/link_mm.stl"], ("likely millimetres", "0.25")),
    Case("part-no-triangles", ["part", "--mesh", R + "/notamesh.stl"], ("no triangles",)),
    Case("part-too-broken", ["part", "--mesh", R + "/link_broken.stl"], ("too broken", "CAD")),
    Case("part-missing-mesh", ["part", "--mesh", R + "/nope.stl"], ("nope.stl", "not found")),
    Case(
        "part-views", ["part", "plate", "--views", "up", "--png", R + "/p.png"], ("--views", "+x")
    ),
    Case("part-out-ro", ["part", "plate", "--out", R + "/ro/p"], ("--out", "read-only"), read_only),
    Case("probe-n-forces", ["probe", "--part", "plate", "--n-forces", "0"], ("--n-forces 0",)),
    Case("probe-seed-negative", ["probe", "--part", "plate", "--seed", "-1"], ("--seed -1",)),
    Case(
        "probe-png-ro",
        ["probe", "--part", "plate", "--png", R + "/ro/c.png"],
        ("read-only",),
        read_only,
    ),
    Case("assets-ro", ["assets", "--out", R + "/ro/a"], ("--out", "read-only"), read_only),
    # generate and merge
    Case(
        "generate-ro",
        ["generate", "--out", R + "/ro/g", "--config", R + "/small.toml"],
        ("--out", "read-only"),
        read_only,
    ),
    Case(
        "generate-mm-mesh",
        ["generate", "--out", R + "/g", "--part", R + "/link_mm.stl", "--n", "4"],
        ("likely millimetres",),
    ),
    Case("generate-n", ["generate", "--out", R + "/g", "--n", "0"], ("--n 0", "out of range")),
    Case(
        "generate-other-seed",
        ["generate", "--out", R + "/ds", "--config", R + "/small.toml", "--seed", "9"],
        ("another configuration", "seed"),
    ),
    Case(
        "generate-full",
        [
            "generate",
            "--out",
            R + "/g",
            "--config",
            R + "/small.toml",
            "--workers",
            "1",
            "--no-progress",
        ],
        ("disk is full", "chunk_", "about", "resumes"),
        full_disk(0, only="chunk_000002"),
        writes=True,
    ),
    Case("merge-ro", ["merge", R + "/ds", "--out", R + "/ro/m"], ("read-only",), read_only),
    Case("merge-no-shard", ["merge", R + "/nope", "--out", R + "/m"], ("nope", "manifest")),
    Case(
        "merge-full",
        ["merge", R + "/ds", "--out", R + "/m"],
        ("disk is full", "dataset.h5", "about"),
        full_disk(20_000),
        writes=True,
    ),
    # export
    Case(
        "export-nonempty",
        ["export", R + "/ds", "--out", R + "/nonempty"],
        ("not empty", "export.json"),
    ),
    Case(
        "export-other",
        ["export", R + "/other", "--out", R + "/exp"],
        ("export of", "other", "would mix"),
    ),
    Case(
        "export-damaged",
        ["export", R + "/bad", "--out", R + "/e"],
        ("field 'image'", "sample 5", "Fix:"),
        writes=True,
    ),
    Case("export-ro", ["export", R + "/ds", "--out", R + "/ro/e"], ("read-only",), read_only),
    Case(
        "export-full",
        ["export", R + "/ds", "--out", R + "/e", "--no-progress"],
        ("disk is full", ".png", "resumes"),
        full_disk(3_000),
        writes=True,
    ),
    # ingest, sheet, view, verify
    Case(
        "ingest-binary",
        ["ingest", R + "/binary.csv", R + "/frames.csv", "--out", R + "/i"],
        ("binary.csv", "not a text"),
    ),
    Case(
        "ingest-into-dataset",
        ["ingest", R + "/layout.csv", R + "/frames.csv", "--out", R + "/ds"],
        ("another configuration",),
    ),
    Case(
        "ingest-ro",
        ["ingest", R + "/layout.csv", R + "/frames.csv", "--out", R + "/ro/i"],
        ("read-only",),
        read_only,
    ),
    Case(
        "sheet-damaged",
        ["sheet", R + "/bad", "--png", R + "/s.png", "--n", "12"],
        ("field 'image'", "sample 5"),
    ),
    Case("sheet-png-folder", ["sheet", R + "/ds", "--png", R + "/ds"], ("is a folder",)),
    Case(
        "sheet-no-subjects",
        ["sheet", R + "/ing", "--png", R + "/s.png", "--subject", "3"],
        ("no 'subject_id' field", "--subject"),
    ),
    Case(
        "sheet-full",
        ["sheet", R + "/ds", "--png", R + "/s.png"],
        ("disk is full", "s.png"),
        full_disk(0),
    ),
    Case(
        "view-sample",
        ["view", R + "/ds", "--sample", "99", "--panel", R + "/v.png"],
        ("--sample 99",),
    ),
    Case(
        "view-panel-ro",
        ["view", R + "/ds", "--panel", R + "/ro/v.png"],
        ("--panel", "read-only"),
        read_only,
    ),
    Case("verify-missing", ["verify", R + "/nope"], ("no dataset",)),
    # train, evaluate, predict, quantize, experiment
    Case(
        "train-best-only",
        ["train", R + "/ds", "--out", R + "/best_only", "--resume"],
        ("best.pt but no last.pt", "mv"),
    ),
    Case(
        "train-best-only-fresh",
        ["train", R + "/ds", "--out", R + "/best_only"],
        ("best.pt but no last.pt",),
    ),
    Case(
        "train-resume-nothing",
        ["train", R + "/ds", "--out", R + "/fresh", "--resume"],
        ("--resume", "no last.pt", "leave"),
    ),
    Case(
        "train-resume-other-data",
        ["train", R + "/other", "--out", R + "/run", "--resume", "--config", R + "/run.toml"],
        ("/ds", "/other", "another --out"),
    ),
    Case(
        "train-over-a-run",
        ["train", R + "/ds", "--out", R + "/run", "--config", R + "/run.toml"],
        ("already holds a run", "--resume"),
    ),
    Case("train-ro", ["train", R + "/ds", "--out", R + "/ro/r"], ("read-only",), read_only),
    Case(
        "train-batch-size",
        ["train", R + "/ds", "--out", R + "/t", "--batch-size", "0"],
        ("--batch-size",),
    ),
    Case("train-one-class", ["train", R + "/objects", "--out", R + "/t"], ("non_hand only",)),
    Case(
        "train-damaged",
        ["train", R + "/bad", "--out", R + "/t", "--config", R + "/run.toml", "--no-progress"],
        ("field 'image'", "sample 5"),
    ),
    Case(
        "train-full",
        ["train", R + "/ds", "--out", R + "/t", "--config", R + "/run.toml", "--no-progress"],
        ("disk is full", "best.pt"),
        full_disk(10**6),
        writes=True,
    ),
    Case(
        "evaluate-ro",
        ["evaluate", R + "/ds", R + "/run/best.pt", "--out", R + "/ro/r.md"],
        ("read-only",),
        read_only,
    ),
    Case(
        "evaluate-not-checkpoint",
        ["evaluate", R + "/ds", R + "/notes.png"],
        ("notes.png", "not a readable checkpoint"),
    ),
    Case(
        "predict-text-image",
        ["predict", R + "/text.jpg", "--classifier", R + "/run/best.pt"],
        ("text.jpg", "not a readable image"),
    ),
    Case(
        "predict-png-ro",
        [
            "predict",
            R + "/ds",
            "--sample",
            "0",
            "--classifier",
            R + "/run/best.pt",
            "--png",
            R + "/ro/p.png",
        ],
        ("read-only",),
        read_only,
    ),
    Case(
        "quantize-ro",
        ["quantize", R + "/run/best.pt", "--out", R + "/ro/q.pt"],
        ("read-only",),
        read_only,
    ),
    Case("quantize-not-checkpoint", ["quantize", R + "/notes.png"], ("not a readable",)),
    Case(
        "experiment-ro",
        ["experiment", "robustness-a", R + "/ds", "--out", R + "/ro/x", "--quick"],
        ("read-only",),
        read_only,
    ),
]
# An output never writes over what the command reads, nor over a dataset's or a run's files, and
# its suffix names what is written (tactile.files.require_output): the examples and the
# cases around them (links, "..", files written beside the output, folders).
READS = ("write over a file this command reads",)
EV = ["evaluate", R + "/ds", R + "/run/best.pt", "--out"]
PR = ["predict", R + "/ds", "--sample", "0", "--classifier", R + "/run/best.pt", "--png"]
FRAME = ["predict", R + "/frame.npy", "--map", R + "/ds"]
OUTPUT_CASES = [
    Case("view-png-over-dataset", ["view", R + "/ds", "--png", R + "/ds/dataset.h5"], READS),
    Case("view-png-dotdot", ["view", R + "/ds", "--png", R + "/run/../ds/info.json"], READS),
    Case("view-png-link-to-input", ["view", R + "/ds", "--png", R + "/link.png"], ("links to",)),
    Case("view-panel-suffix", ["view", R + "/ds", "--panel", R + "/v.svgz"], (".png suffix",)),
    Case("view-sequence-suffix", ["view", R + "/ds", "--sequence", R + "/s.mp4"], (".gif or",)),
    Case("evaluate-out-checkpoint", [*EV, R + "/run/best.pt"], READS),
    Case("evaluate-threads-huge", [*EV, R + "/r.md", "--threads", "10" * 10], ("--threads",)),
    Case(
        "evaluate-hand-classes-on-a-dataset",
        [*EV, R + "/r.md", "--hand-classes", "hand"],
        ("--hand-classes hand", "handskin dataset", "drop it"),
    ),
    Case(
        "experiment-out-into-the-dataset",
        ["experiment", "robustness-a", R + "/ds", "--out", R + "/ds", "--quick"],
        ("--out", "is a dataset folder", "give a new --out folder"),
    ),
    Case("evaluate-json-beside", [*EV, R + "/ds/info.md"], ("also write", "info.json", *READS)),
    Case("evaluate-json-run-file", [*EV, R + "/run/test_metrics.md"], ("of the run folder",)),
    Case("evaluate-out-suffix", [*EV, R + "/report.txt"], (".md suffix", "report.md")),
    Case("stats-out-info", ["stats", R + "/ds", "--out", R + "/ds/info.json"], READS),
    Case("stats-out-dataset", ["stats", R + "/ds", "--out", R + "/ds/dataset.h5"], READS),
    Case("stats-out-suffix", ["stats", R + "/ds", "--out", R + "/s.png"], (".md suffix",)),
    Case("stats-png-run-file", ["stats", R + "/ds", "--png", R + "/run/curves.png"], ("run",)),
    Case("sheet-png-dataset", ["sheet", R + "/ds", "--png", R + "/ds/dataset.h5"], READS),
    Case("sheet-png-suffix", ["sheet", R + "/ds", "--png", R + "/s.pdfx"], (".png suffix",)),
    Case(
        "sheet-png-other-dataset", ["sheet", R + "/ds", "--png", R + "/other/info.json"], ("other",)
    ),
    Case(
        "predict-out-over-frame",
        [*FRAME, "--segmenter", R + "/run/best.pt", "--out", R + "/frame.npy"],
        READS,
    ),
    Case("predict-png-checkpoint", [*PR, R + "/run/best.pt"], READS),
    Case("predict-png-run-file", [*PR, R + "/run/curves.png"], ("curves.png of the run",)),
    Case("predict-png-suffix", [*PR, R + "/p.tiff"], (".png suffix",)),
    Case("map-out-over-layout", ["map", R + "/layout.npz", "--out", R + "/layout.npz"], READS),
    Case("map-png-over-layout", ["map", R + "/layout.csv", "--png", R + "/layout.csv"], READS),
    Case("map-png-suffix", ["map", R + "/layout.csv", "--png", R + "/m.xyz"], (".png suffix",)),
    Case("part-png-dataset", ["part", "plate", "--map-png", R + "/ds/dataset.h5"], ("dataset",)),
    Case("probe-png-dataset", ["probe", "--png", R + "/ds/manifest.json"], ("manifest.json of",)),
    Case("export-out-input", ["export", R + "/ds", "--out", R + "/ds"], ("folder this command",)),
    Case("train-out-input", ["train", R + "/ds", "--out", R + "/ds"], ("folder this command",)),
    Case("train-out-chunks", ["train", R + "/ds", "--out", R + "/ds/chunks"], ("dataset folder",)),
    Case(
        "ingest-out-run",
        ["ingest", R + "/layout.csv", R + "/frames.csv", "--out", R + "/run"],
        ("run folder",),
    ),
    Case("assets-out-dataset", ["assets", "--out", R + "/ds"], ("dataset folder",)),
]
CASES += OUTPUT_CASES
# configuration files and numbers read at the boundary, in the words of the flag typed
T = ["train", R + "/ds", "--out", R + "/t"]
CASES += [
    Case(
        "generate-config-binary",
        ["generate", "--out", R + "/g", "--config", R + "/binary.csv"],
        ("binary.csv: not a TOML file", "binary"),
    ),
    Case("train-config-binary", [*T, "--config", R + "/binary.csv"], ("not a TOML file",)),
    Case("train-seed-negative", [*T, "--seed", "-1"], ("--seed -1 is out of range",)),
    Case("train-seed-too-large", [*T, "--seed", str(2**70)], ("--seed", "out of range")),
    Case(
        "train-cv-folds-1",
        [*T, "--cv-grid", "train.lr=0.1,0.01", "--cv-folds", "1"],
        ("--cv-folds 1",),
    ),
    Case(
        "train-arch-against-toml",
        [*T, "--config", R + "/vgg.toml", "--arch", "handsnet"],
        ("--arch handsnet", "'vgg16'", "drop --arch"),
    ),
    Case(
        "train-hand-classes-dataset",
        [*T, "--hand-classes", "hand"],
        ("--hand-classes hand", "handskin dataset"),
    ),
    Case(
        "stream-threshold-nan",
        ["stream", "--map", R + "/ds", "--classifier", R + "/run/best.pt", "--threshold-pa", "nan"],
        ("--threshold-pa",),
    ),
    Case("map-closed-surface", ["map", R + "/sphere.csv"], ("closed surface", "strip")),
    Case(
        "generate-no-taxel-answers",
        ["generate", "--out", R + "/deaf", "--config", R + "/deaf.toml", "--no-progress"],
        ("episode.active_pa (now 999999 Pa", "max_attempts"),
        writes=True,
    ),
]
# verify reads each sidecar's structure before using it: a fault (status 1), no traceback
CASES += [
    Case("verify-info-null", ["verify", R + "/info_null"], ("info.json: null",), status=1),
    Case("verify-info-list", ["verify", R + "/info_list"], ("info.json: a list",), status=1),
    Case("verify-sha-number", ["verify", R + "/sha_number"], ("sha256 the number 1",), status=1),
    Case("verify-content-text", ["verify", R + "/content_text"], ("content is text",), status=1),
    Case("verify-config-edited", ["verify", R + "/n_edited"], ("was edited",), status=1),
    Case(
        "verify-unmerged-gap", ["verify", R + "/unmerged"], ("chunk_000001.h5: missing",), status=1
    ),
]
# Frames of impossible raw counts for a dataset's map, refused as handskin ingest refuses them
COUNTS = ("outside 0..65535", "raw counts")
CLF = ["--map", R + "/ds", "--classifier", R + "/run/best.pt"]
CASES += [
    Case("predict-negative-counts", ["predict", R + "/frame_neg.csv", *CLF], COUNTS),
    Case("predict-counts-above-16-bit", ["predict", R + "/frame_big.csv", *CLF], COUNTS),
    Case("predict-counts-1e300", ["predict", R + "/frame_1e300.npy", *CLF], ("1e+300", *COUNTS)),
]
CASES += [
    Case(
        "finetune-not-box-folder",
        ["finetune", R + "/ds", "--init", R + "/run/best.pt", "--out", R + "/ft"],
        ("REAL", "not a box folder", "ingest-boxes"),
    ),
]
TEMPORARY = (".tmp", files.STAGE_PREFIX)
COMMANDS = ("map", "part", "probe", "assets", "generate", "merge", "export", "ingest", "sheet")
COMMANDS += ("view", "verify", "train", "finetune", "evaluate", "predict", "quantize")
COMMANDS += ("experiment",)


def snapshot(root: Path) -> dict[str, str]:
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_bad_input_is_answered_and_nothing_is_lost(case: Case, world, monkeypatch) -> None:
    root = world["root"]
    before = snapshot(root)
    if case.patch is not None:
        case.patch(monkeypatch, world)
    res = invoke(*(a.format(root=root) for a in case.args))
    monkeypatch.undo()
    after = snapshot(root)
    assert res.exit_code == case.status, res.output
    assert not isinstance(res.exception, Exception), res.exception  # SystemExit(2) only
    assert "Traceback" not in res.output
    missing = [w for w in case.words if w not in res.output]
    assert not missing, f"{missing} not in: {res.output}"
    changed = sorted(p for p in before if after.get(p) != before[p])
    assert not changed, changed
    temporary = [p for p in after if any(t in p for t in TEMPORARY)]
    assert not temporary, temporary
    if not case.writes:
        assert sorted(set(after) - set(before)) == []


def test_the_table_covers_the_subcommands_with_forty_inputs_or_more() -> None:
    tried = {c.args[0] for c in CASES}
    assert len(CASES) >= 40 and tried >= set(COMMANDS), set(COMMANDS) - tried
    registered = {c.name for c in app.registered_commands} | {"experiment"}
    assert set(COMMANDS) <= registered


def test_the_output_rule_knows_every_file_of_a_dataset_and_a_run(world) -> None:
    """`tactile.files` names the files of dataset and run folders as their writers do: every
    file and folder a generated dataset and a trained run hold."""
    from learn.classical.svm import MODEL_FILE
    from learn.train.checkpoint import BEST, LAST
    from tactile.dataset.folder import DATASET
    from tactile.dataset.manifest import MANIFEST

    assert set(files.DATASET_MARKS) == {DATASET, MANIFEST}
    assert set(files.RUN_MARKS) == {BEST, LAST, MODEL_FILE}
    assert {p.name for p in world["ds"].iterdir()} <= set(files.DATASET_FILES)
    assert {p.name for p in world["run"].iterdir()} <= set(files.RUN_FILES)
    assert files.folder_kind(world["ds"])[0] == "dataset"
    assert files.folder_kind(world["run"])[0] == "run"


def test_output_that_is_nonsense_is_said(world, tmp_path) -> None:
    """A generation whose every image is blank (a skin noise that hides each press) and a canvas
    that cuts away most of the map are warned in the user's words; the command still runs."""
    config = ("--config", world["root"] / "noisy.toml", "--workers", 1, "--no-progress")
    res = invoke("generate", "--out", tmp_path / "g", *config)
    assert res.exit_code == 0, res.output
    assert "warning: 12 of 12 tactile images are blank" in res.output, res.output
    assert "noise_std_counts" in res.output
    res = invoke("generate", "--out", tmp_path / "fine", "--config", world["root"] / "small.toml")
    assert res.exit_code == 0 and "warning" not in res.output, res.output
    run = ("--config", world["root"] / "run.toml", "--no-progress")
    res = invoke("train", world["ds"], "--out", tmp_path / "t", *run, "--canvas-mm", "10,10")
    assert res.exit_code == 0, res.output
    assert "warning: the canvas of 10 x 10 mm" in res.output and "% of the" in res.output
