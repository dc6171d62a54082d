"""Killed and resumed: `handskin export` and the merge of chunks, each SIGKILLed mid-run, then run
again, give the same files as an uninterrupted run and leave no temporary file (as
tests/sim/test_generate.py checks for generate). On a real full disk (a 256 kB tmpfs, where
this machine lets a user namespace mount one) generate stops with one line, no crash."""

from __future__ import annotations

import hashlib
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from tactile import TactileMap
from tactile.dataset import DatasetWriter, export_png
from tactile.dataset.merge import merge_chunks
from tactile.geometry.synthetic import cylinder_sector_layout

ROOT = Path(__file__).resolve().parents[2]
N, PER_CHUNK = 240, 20  # noise images of 240 x 360 px: seconds to merge and to export


@pytest.fixture(scope="module")
def chunks(tmp_path_factory) -> Path:
    """A dataset folder with its chunks written and not merged (incompressible images)."""
    folder = tmp_path_factory.mktemp("kill") / "chunks_only"
    layout, _ = cylinder_sector_layout(width_mm=60, length_mm=90, pitch_mm=5)
    tmap = TactileMap.build(layout, step_mm=0.25)
    writer = DatasetWriter(
        folder, config={"test": "kill"}, part="p", generator_version="t", seed=2,
        tmap=tmap, layout=layout,
    )  # fmt: skip
    rng = np.random.default_rng(0)
    for k in range(N // PER_CHUNK):
        rows = [
            {
                "raw": rng.integers(0, 900, layout.n_taxels).astype(np.uint16),
                "pressure_pa": np.zeros(layout.n_taxels, np.float32),
                "image": rng.integers(0, 256, tmap.shape).astype(np.uint8),
                "is_hand": np.uint8(i % 2),
                "subject_id": np.int32(i // 8 if i % 2 else -1),
                "instance_id": np.int32(-1 if i % 2 else i // 8),
            }
            for i in range(k * PER_CHUNK, (k + 1) * PER_CHUNK)
        ]
        writer.write_chunk(k, rows)
    return folder


def digests(folder: Path) -> dict[str, str]:
    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def temporaries(folder: Path) -> list[Path]:
    return [p for p in folder.rglob("*") if ".tmp" in p.name or p.name.startswith(".handskin-")]


def kill_when(argv: list[str], ready, timeout_s: float = 60.0) -> None:
    """Run ``argv``; SIGKILL it as soon as ``ready()`` holds (it must still be running)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen(argv, cwd=ROOT, env=env, stderr=subprocess.PIPE)
    end = time.monotonic() + timeout_s
    try:
        while not ready():
            assert proc.poll() is None, f"ended before the kill: {proc.stderr.read().decode()}"
            assert time.monotonic() < end, "not ready in time"
            time.sleep(0.005)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()


def test_a_merge_killed_midway_then_rerun_equals_an_uninterrupted_one(chunks, tmp_path):
    reference = tmp_path / "reference"
    shutil.copytree(chunks, reference)
    merge_chunks(reference)
    killed = tmp_path / "killed"
    shutil.copytree(chunks, killed)
    code = "import sys; from tactile.dataset.merge import merge_chunks; merge_chunks(sys.argv[1])"
    started = lambda: any(p.stat().st_size > 10**6 for p in killed.glob(".dataset.h5.*"))  # noqa: E731
    kill_when([sys.executable, "-c", code, str(killed)], started)
    assert not (killed / "dataset.h5").exists() and temporaries(killed)  # cut short
    merge_chunks(killed)
    assert digests(killed) == digests(reference)
    assert not temporaries(killed)


def test_an_export_killed_midway_then_rerun_equals_an_uninterrupted_one(chunks, tmp_path):
    dataset = tmp_path / "ds"
    shutil.copytree(chunks, dataset)
    merge_chunks(dataset)
    reference, killed = tmp_path / "reference", tmp_path / "killed"
    export_png(dataset, reference)
    code = "from handskin.cli import main; main()"
    argv = [sys.executable, "-c", code, "export", str(dataset), "--out", str(killed)]
    kill_when([*argv, "--no-progress"], lambda: len(list(killed.rglob("*.png"))) >= 20)
    assert 20 <= len(list(killed.rglob("*.png"))) < N
    written = export_png(dataset, killed)  # resumes: the files already there are kept
    assert written == {"hand": N // 2, "non_hand": N // 2}
    assert digests(killed) == digests(reference)
    assert not temporaries(killed)


def _can_mount_tmpfs() -> bool:
    try:
        probe = subprocess.run(
            ["unshare", "-rm", "sh", "-c", "mount -t tmpfs -o size=4k tmpfs /mnt"],
            capture_output=True,
            timeout=10,
        )
    except (OSError, subprocess.TimeoutExpired):
        return False
    return probe.returncode == 0


@pytest.mark.skipif(not _can_mount_tmpfs(), reason="no user namespace to mount a tmpfs in")
def test_generate_on_a_really_full_disk_stops_with_one_line(tmp_path):
    """A 256 kB tmpfs holds the manifest and a chunk or two of the small plate dataset; the run
    stops with exit status 2 and one error line naming the chunk and the space, no crash, no
    temporary file; the chunks already written stay for the resume."""
    disk = tmp_path / "disk"
    disk.mkdir()
    config = tmp_path / "small.toml"
    config.write_text(
        'part = "plate"\nn = 12\nchunk_size = 3\nn_subjects = 3\ninstances_per_kind = 2\n'
        "duration_scale = 0.5\nseed = 5\n[episode]\nmax_attempts = 20\n"
    )
    generate = f"{sys.executable} -c 'from handskin.cli import main; main()' generate"
    script = (
        f"mount -t tmpfs -o size=256k tmpfs {disk} && head -c 40000 /dev/zero > {disk}/filler && "
        f"{generate} --out {disk}/ds --config {config} --workers 2 --no-progress; "
        f"echo rc=$?; ls -a {disk}/ds/chunks"
    )
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    res = subprocess.run(["unshare", "-rm", "sh", "-c", script], capture_output=True, text=True,
                         env=env, cwd=ROOT, timeout=300)  # fmt: skip
    assert "rc=2" in res.stdout, res.stdout + res.stderr
    errors = [line for line in res.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "the disk is full" in errors[0] and "chunk_" in errors[0]
    assert "Traceback" not in res.stderr and ".tmp" not in res.stdout
