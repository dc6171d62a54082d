"""Damage found and named: HDF5 fletcher32 checksums, the manifest's content hash, `handskin
verify`, read errors naming file, field and sample; older datasets without checksums still read;
files honour the umask."""

from __future__ import annotations

import json
import os
import stat

import h5py
import numpy as np
import pytest
import typer
from typer.testing import CliRunner

import tactile.dataset.h5io as h5io
from tactile import TactileMap
from tactile.cli.dataset import register
from tactile.dataset import DatasetWriter, open_dataset
from tactile.dataset.merge import merge_chunks
from tactile.dataset.verify import verify_dataset
from tactile.errors import DataError
from tactile.geometry.synthetic import cylinder_sector_layout

N = 8  # samples: hands (even, subjects 0..3) and objects (odd, instances 0..3)


def write(folder, chunks: int = 2):
    """A small dataset in ``folder`` (``chunks`` chunks of N // chunks samples)."""
    layout, _ = cylinder_sector_layout(width_mm=50, length_mm=70, pitch_mm=8)
    tmap = TactileMap.build(layout)
    rng = np.random.default_rng(4)
    writer = DatasetWriter(
        folder,
        config={"test": "verify"},
        part="p",
        generator_version="t",
        seed=1,
        tmap=tmap,
        layout=layout,
    )
    per = N // chunks
    for k in range(chunks):
        rows = []
        for i in range(k * per, (k + 1) * per):
            p = rng.uniform(0, 200, layout.n_taxels) * (rng.uniform(size=layout.n_taxels) < 0.3)
            hand = i % 2 == 0
            rows.append(
                {
                    "raw": p.astype(np.uint16),
                    "pressure_pa": p.astype(np.float32),
                    "image": tmap.image(p),
                    "is_hand": np.uint8(hand),
                    "subject_id": np.int32(i // 2 if hand else -1),
                    "instance_id": np.int32(-1 if hand else i // 2),
                }
            )
        writer.write_chunk(k, rows)
    writer.merge()
    return folder


def flip(path, offset: int) -> None:
    data = bytearray(path.read_bytes())
    data[offset] ^= 0x10
    path.write_bytes(bytes(data))


def chunk_offset(path, dataset: str, index: tuple[int, ...]) -> int:
    with h5py.File(path, "r") as f:
        info = f[dataset].id.get_chunk_info_by_coord(index)
    return info.byte_offset + info.size // 2


@pytest.fixture
def dataset(tmp_path):
    return write(tmp_path / "ds")


def run_verify(path):
    app = typer.Typer()
    register(app)
    return CliRunner().invoke(app, ["verify", str(path), "--no-progress"])


def test_a_clean_dataset_verifies_with_checksums_on_every_array(dataset):
    res = run_verify(dataset)
    assert res.exit_code == 0, res.output
    assert "content hash of dataset.h5, info.json matches manifest.json" in res.output
    assert "HDF5 fletcher32 checksums on all" in res.output and "no fault found" in res.output
    manifest = json.loads((dataset / "manifest.json").read_text())
    assert manifest["content"]["dataset.h5"]["bytes"] == (dataset / "dataset.h5").stat().st_size


def test_a_flipped_byte_in_a_sample_is_named_by_verify_and_by_every_read(dataset):
    file = dataset / "dataset.h5"
    flip(file, chunk_offset(file, "samples/image", (5, 0, 0)))
    res = run_verify(dataset)
    assert res.exit_code == 1
    assert "field 'image' of sample 5 cannot be read (checksum mismatch" in res.output
    assert "matches manifest.json" not in res.output  # the content hash differs too
    assert f"handskin merge {dataset} --out {dataset}" in res.output  # the fix: chunks are there
    with open_dataset(dataset) as ds:
        np.testing.assert_array_equal(ds[4]["image"].shape, ds.map.shape)  # neighbours read
        for read in (lambda: ds[5], lambda: ds.image[()], lambda: ds["image"][3:7]):
            with pytest.raises(DataError, match=r"dataset.h5: field 'image' of sample 5"):
                read()


def test_a_flipped_byte_in_the_map_or_outside_the_data_is_found(dataset, tmp_path):
    file = dataset / "dataset.h5"
    flip(file, chunk_offset(file, "map/uv", (0, 0)))
    res = run_verify(dataset)
    assert res.exit_code == 1 and "the map cannot be read" in res.output
    other = write(tmp_path / "other")
    text = (other / "dataset.h5").read_bytes()
    flip(other / "dataset.h5", text.index(b'"test":"verify"') + 9)  # inside the config attr
    res = run_verify(other)
    assert res.exit_code == 1, res.output
    assert "but its merge wrote sha256" in res.output and "the file changed since" in res.output


def test_a_damaged_chunk_names_the_chunk_to_delete_and_resume(dataset):
    chunk = dataset / "chunks" / "chunk_000001.h5"
    flip(chunk, chunk_offset(chunk, "samples/raw", (2, 0)))
    res = run_verify(dataset)
    assert res.exit_code == 1
    assert f"delete {chunk} and rerun the same handskin generate --out {dataset}" in res.output
    (dataset / "dataset.h5").unlink()
    with pytest.raises(DataError, match=r"chunk_000001.h5: field 'raw' of sample 2"):
        merge_chunks(dataset)


def test_an_older_dataset_without_checksums_reads_and_verifies(tmp_path, monkeypatch):
    plain = {"compression": "gzip", "compression_opts": 4, "shuffle": True}
    monkeypatch.setattr(h5io, "filters", lambda dtype, level=4: {} if dtype == "str" else {**plain})
    monkeypatch.setattr(
        h5io,
        "plain_dataset",
        lambda parent, name, data: parent.create_dataset(name, data=data, track_times=False),
    )
    old = write(tmp_path / "old")
    manifest = json.loads((old / "manifest.json").read_text())
    del manifest["content"]
    (old / "manifest.json").write_text(json.dumps(manifest))
    monkeypatch.undo()
    report = verify_dataset(old)
    assert not report.faults
    assert any("no HDF5 checksum" in n for n in report.notes)
    assert any("no content hash" in n for n in report.notes)
    with open_dataset(old) as ds:
        assert ds[3]["image"].shape == ds.map.shape
    file = old / "dataset.h5"
    flip(file, chunk_offset(file, "samples/image", (2, 0, 0)))
    with open_dataset(old) as ds, pytest.raises(DataError, match="this older file has no"):
        ds.image[2]


@pytest.mark.parametrize("umask", [0o022, 0o002])
def test_files_honour_the_umask(tmp_path, umask):
    old = os.umask(umask)
    try:
        folder = write(tmp_path / "ds")
    finally:
        os.umask(old)
    for name in ("dataset.h5", "info.json", "manifest.json", "chunks/chunk_000000.h5"):
        assert stat.S_IMODE((folder / name).stat().st_mode) == 0o666 & ~umask, name
