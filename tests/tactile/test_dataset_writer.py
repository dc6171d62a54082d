"""Dataset writer, merge and reader: round trip, reproducible bytes, resume, refusal, schema."""

from __future__ import annotations

import hashlib
import json
import pickle
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from tactile import TactileMap
from tactile.dataset import (
    DatasetWriter,
    Dims,
    chunk_path,
    list_chunks,
    merge_chunks,
    open_dataset,
    validate_sample,
)
from tactile.errors import DataError
from tactile.geometry.synthetic import cylinder_sector_layout

CHUNKS = ((0, 7), (7, 14), (14, 20))  # sample ranges of the 3 chunks
SEQ_LEN = 4


@pytest.fixture(scope="module")
def part():
    layout, _ = cylinder_sector_layout(width_mm=60, length_mm=90, pitch_mm=8)
    return layout, TactileMap.build(layout)


def make_sample(tmap: TactileMap, i: int) -> dict:
    """Sample i with every field, from its own seed (an independent reference for read-back)."""
    rng = np.random.default_rng(1000 + i)
    n, hand = tmap.n_taxels, i % 2
    p = rng.uniform(0.0, 2000.0, n) * (rng.uniform(size=n) < 0.3)
    labels = rng.integers(1, 7, n).astype(np.uint8) * (p > 0) * hand
    return {
        "raw": (4000 + p).astype(np.uint16),
        "pressure_pa": p.astype(np.float32),
        "taxel_label": labels.astype(np.uint8),
        "taxel_contactor": np.where(p > 0, 0, -1).astype(np.int16),
        "image": tmap.image(p),
        "label_image": tmap.label_image(p, labels) if hand else np.zeros(tmap.shape, np.uint8),
        "is_hand": np.uint8(hand),
        "action": np.int8(i % 3 if hand else -1),
        "operator_position": np.int8(i % 3 if hand else -1),
        "subject_id": np.int32(i // 4 if hand else -1),
        "instance_id": np.int32(-1 if hand else i // 4),
        "contactor": json.dumps({"kind": "hand" if hand else "sphere", "i": i, "name": "é"}),
        "episode_seed": np.uint64(2**63 + i),
        "force_n": np.float32(rng.uniform(1, 10)),
        "time_s": np.float32(i * 0.1),
        "seq_raw": rng.integers(0, 65536, (SEQ_LEN, n)).astype(np.uint16),
        "seq_length": np.int16(i % (SEQ_LEN + 1)),
    }


def writer(folder: Path, part, config: dict | None = None) -> DatasetWriter:
    layout, tmap = part
    return DatasetWriter(
        folder,
        config=config or {"episodes": 20, "skin": {"noise": 0.01}},
        part="sector",
        generator_version="test-1",
        seed=11,
        tmap=tmap,
        layout=layout,
        seq_len=SEQ_LEN,
        attrs={
            "skin_counts_per_pa": 0.5,
            "skin_baseline_counts": 4000.0,
            "actions": ["grasp", "poke", "slide"],
        },
    )


def write_all(folder: Path, part, chunks=(0, 1, 2)) -> DatasetWriter:
    w = writer(folder, part)
    for k in chunks:
        lo, hi = CHUNKS[k]
        w.write_chunk(k, [make_sample(part[1], i) for i in range(lo, hi)], rejects={"slip": k})
    return w


def sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def snapshot(folder: Path) -> dict:
    return {p: (p.stat().st_mtime_ns, p.read_bytes()) for p in folder.rglob("*") if p.is_file()}


def test_round_trip_equals_what_was_written(tmp_path, part):
    layout, tmap = part
    path = write_all(tmp_path / "ds", part).merge()
    ds = open_dataset(tmp_path / "ds")
    assert len(ds) == 20
    for i in range(20):
        want, got = make_sample(tmap, i), ds[i]
        assert set(got) == set(want)
        for key, value in want.items():
            if key == "contactor":
                assert got[key] == value
            else:
                np.testing.assert_array_equal(got[key], value, err_msg=key)
    with h5py.File(path, "r") as f:  # plain h5py, no handskin code
        assert f["samples/image"].chunks == (1, *tmap.shape)
        assert f["samples/raw"].compression == "gzip" and f["samples/raw"].shuffle
        assert f["sequences/raw"].shape == (20, SEQ_LEN, layout.n_taxels)
        assert json.loads(f.attrs["rejects"]) == {"slip": 3}
        assert f.attrs["seed"] == 11 and f.attrs["part"] == "sector"
    p = make_sample(tmap, 3)["pressure_pa"]
    np.testing.assert_array_equal(ds.map.image(p), tmap.image(p))
    np.testing.assert_array_equal(ds.layout.positions_m, layout.positions_m)
    assert ds.attrs["config"] == {"episodes": 20, "skin": {"noise": 0.01}}
    assert ds.attrs["class_balance"]["samples"] == {"hand": 10, "non_hand": 10}
    assert "numpy" in ds.attrs["versions"] and "mujoco" in ds.attrs["versions"]


@pytest.mark.parametrize(
    ("config", "want_pa"),
    [
        ({"episode": {"active_pa": 612.5}}, 612.5),  # a synthetic dataset's generation config
        ({"episodes": 20}, 0.0),  # no threshold recorded
        ({"episode": {"active_pa": "high"}}, 0.0),  # not a number
    ],
)
def test_active_threshold_is_the_configs_active_pa(tmp_path, part, config, want_pa):
    w = writer(tmp_path / "ds", part, config)
    w.write_chunk(0, [make_sample(part[1], i) for i in range(3)])
    w.merge()
    with open_dataset(tmp_path / "ds") as ds:
        assert ds.active_threshold_pa == want_pa


def test_field_access_info_and_pickle(tmp_path, part):
    write_all(tmp_path / "ds", part).merge()
    ds = open_dataset(tmp_path / "ds")
    np.testing.assert_array_equal(ds.raw[2:4], ds["raw"][2:4])
    assert ds.info["fields"]["raw"] == {
        "path": "samples/raw",
        "dtype": "uint16",
        "shape": [part[0].n_taxels],
        "unit": "count",
        "description": ds.info["fields"]["raw"]["description"],
    }
    assert ds.info["fields"]["image"]["shape"] == list(part[1].shape)
    assert ds.info["dims"]["T"] == SEQ_LEN
    _ = ds.map
    clone = pickle.loads(pickle.dumps(ds))
    np.testing.assert_array_equal(clone[5]["image"], ds[5]["image"])
    with pytest.raises(KeyError, match="fields"):
        ds["nope"]
    (tmp_path / "junk.h5").write_bytes(b"not hdf5")
    with pytest.raises(DataError, match=r"cannot open .*junk\.h5 as HDF5"):
        open_dataset(tmp_path / "junk.h5")


def test_pressure_from_raw_uses_the_documented_attrs(tmp_path, part):
    write_all(tmp_path / "ds", part).merge()
    ds = open_dataset(tmp_path / "ds")
    raw = np.array([3000, 4000, 4100], dtype=np.uint16)
    np.testing.assert_allclose(ds.pressure_from_raw(raw), [0.0, 0.0, 200.0])  # (raw-4000)/0.5
    raw = ds.raw[:3]
    want = part[1].image(np.maximum(raw.astype(float) - 4000.0, 0) / 0.5)
    np.testing.assert_array_equal(ds.images_from_raw(raw), want)
    keep = np.arange(0, part[0].n_taxels, 2)
    sub = TactileMap.build(part[0].subset(keep))
    got = ds.images_from_raw(raw, sub, keep=keep)
    np.testing.assert_array_equal(got, sub.image((np.maximum(raw - 4000.0, 0) / 0.5)[:, keep]))


def test_two_independent_writes_give_identical_bytes(tmp_path, part):
    a = write_all(tmp_path / "a", part).merge()
    time.sleep(1.1)  # HDF5 timestamps have 1 s resolution: they would differ now
    b = write_all(tmp_path / "b", part).merge()
    assert sha(a) == sha(b)
    again = merge_chunks(tmp_path / "a")
    assert sha(again) == sha(b)
    assert (tmp_path / "a/info.json").read_bytes() == (tmp_path / "b/info.json").read_bytes()


def test_resume_after_a_kill_mid_chunk(tmp_path, part):
    reference = write_all(tmp_path / "whole", part).merge()
    folder = tmp_path / "killed"
    write_all(folder, part, chunks=[0, 1])
    # the kill: chunk 2 was being written to its temporary name and got cut short
    full = chunk_path(tmp_path / "whole", 2).read_bytes()
    temp = folder / "chunks" / ".chunk_000002.h5.k1ll3d.tmp"
    temp.write_bytes(full[: len(full) // 2])
    assert list_chunks(folder) == [0, 1]
    w = writer(folder, part)
    assert w.resumed and w.complete_chunks() == [0, 1] and not temp.exists()
    with pytest.raises(DataError, match=r"chunk\(s\) \[2\] missing"):  # incomplete: refused
        w.merge(n_chunks=3)
    (folder / "chunks" / "chunk_000000.h5").rename(folder / "chunks" / "hold.h5")
    with pytest.raises(DataError, match=r"chunk\(s\) \[0\] missing"):  # a gap: refused
        w.merge()
    (folder / "chunks" / "hold.h5").rename(folder / "chunks" / "chunk_000000.h5")
    assert not (folder / "dataset.h5").exists()
    for k in sorted(set(range(len(CHUNKS))) - set(w.complete_chunks())):
        lo, hi = CHUNKS[k]
        w.write_chunk(k, [make_sample(part[1], i) for i in range(lo, hi)], rejects={"slip": k})
    assert sha(w.merge()) == sha(reference)


def test_folder_of_another_configuration_is_refused_untouched(tmp_path, part):
    folder = tmp_path / "ds"
    write_all(folder, part).merge()
    before = snapshot(folder)
    with pytest.raises(DataError) as err:
        writer(folder, part, config={"episodes": 20, "skin": {"noise": 0.02}})
    msg = str(err.value)
    assert "skin.noise" in msg and "new --out folder" in msg
    old = json.loads((folder / "manifest.json").read_text())["fingerprint"]
    assert old[:12] in msg
    assert snapshot(folder) == before
    stranger = tmp_path / "stranger"
    stranger.mkdir()
    (stranger / "notes.txt").write_text("mine")
    with pytest.raises(DataError, match=r"no manifest\.json"):
        writer(stranger, part)
    assert [p.name for p in stranger.iterdir()] == ["notes.txt"]


def _with_nan(a: np.ndarray) -> np.ndarray:
    a = a.copy()
    a[3] = np.nan
    return a


BREAKS = {  # field -> (break the sample's value, expected message)
    "raw": (lambda v: v[:5], r"'raw': expected shape \(104,\) \(uint16\), got \(5,\)"),
    "raw_float": (lambda v: v + 0.5, r"'raw': expected uint16 \(count\), got float64"),
    "pressure_pa": (_with_nan, r"'pressure_pa': NaN or inf .* at index \(3,\)"),
    "image": (lambda v: v.astype(np.float32), "'image': expected uint8"),
    "taxel_label": (lambda v: v + 9, r"'taxel_label': values must lie in 0..6"),
    "is_hand": (lambda v: np.uint8(2), r"'is_hand': values must lie in 0..1"),
    "colour": (lambda v: np.uint8(1), "unknown field 'colour'; known fields: raw"),
    "contactor": (lambda v: 5, "'contactor': expected a str"),
}


@pytest.mark.parametrize("case", sorted(BREAKS))
def test_schema_errors_name_the_field(tmp_path, part, case):
    w = writer(tmp_path / "ds", part)
    sample = make_sample(part[1], 1)
    key = case.removesuffix("_float")
    breaker, match = BREAKS[case]
    sample[key] = breaker(sample.get(key, sample["raw"].astype(np.float64)))
    with pytest.raises(DataError, match=match) as err:
        w.write_chunk(0, [make_sample(part[1], 0), sample])
    assert "chunk 0, sample 1" in str(err.value)
    assert list_chunks(tmp_path / "ds") == []


def test_missing_required_and_inconsistent_fields(tmp_path, part):
    dims = Dims(part[0].n_taxels, *part[1].shape, SEQ_LEN)
    sample = make_sample(part[1], 0)
    del sample["image"]
    with pytest.raises(DataError, match=r"required field\(s\) \['image'\]"):
        validate_sample(sample, dims)
    w = writer(tmp_path / "ds", part)
    w.write_chunk(0, [make_sample(part[1], 0)])
    fewer = make_sample(part[1], 1)
    del fewer["force_n"]
    with pytest.raises(DataError, match=r"missing \['force_n'\]"):
        w.write_chunk(1, [fewer])
    cast = validate_sample({**make_sample(part[1], 0), "raw": np.full(dims.n_taxels, 7)}, dims)
    assert cast["raw"].dtype == np.uint16
