"""Ingest of real recordings: round trip against TactileMap.image, real iCub layout, errors."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from tactile import TactileMap, TaxelLayout
from tactile.dataset import ingest_recording, open_dataset
from tactile.errors import DataError
from tactile.geometry.synthetic import cylinder_sector_layout

T = 6
EXTRA_CHANNELS = 8  # channels of the raw frame that no taxel reads


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """A synthetic "real recording": layout CSV with channels, channel frames with a known
    pressure blob, baseline frames, class labels and part labels."""
    folder = tmp_path_factory.mktemp("rec")
    base, _ = cylinder_sector_layout(width_mm=60, length_mm=90, pitch_mm=8)
    n = base.n_taxels
    rng = np.random.default_rng(7)
    channels = rng.permutation(n + EXTRA_CHANNELS)[:n]
    layout = TaxelLayout(
        base.positions_m,
        base.normals,
        channel_ids=channels,
        n_channels=n + EXTRA_CHANNELS,
        name="sector",
    )
    layout.save(folder / "layout.csv")
    centres = layout.positions_m[rng.choice(n, T)]
    dist2 = ((layout.positions_m[None] - centres[:, None]) ** 2).sum(-1)
    blob = np.rint(900.0 * np.exp(-dist2 / (2 * 0.012**2)))  # (T, N) counts
    baseline = rng.integers(3000, 5000, n).astype(float)
    chan = rng.integers(0, 65536, (T, n + EXTRA_CHANNELS))
    chan[:, channels] = baseline + blob
    base_frames = np.tile(chan[:1], (3, 1))
    base_frames[:, channels] = baseline + np.array([[-2], [0], [2]])
    write_csv(folder / "frames.csv", chan, header=True)
    np.save(folder / "frames.npy", chan)
    write_csv(folder / "baseline.csv", base_frames)
    hand = np.array([1, 0, 1, 1, 0, 1])
    (folder / "labels.csv").write_text(
        "label\n" + "\n".join(["hand" if h else "non_hand" for h in hand]) + "\n"
    )
    parts = (rng.integers(1, 7, (T, n)) * (blob > 0)).astype(np.int64)
    np.save(folder / "parts.npy", parts)
    return {
        "dir": folder,
        "layout": layout,
        "blob": blob,
        "baseline": baseline,
        "hand": hand,
        "parts": parts,
        "channels": chan,
    }


def write_csv(path: Path, arr: np.ndarray, header: bool = False) -> None:
    lines = [",".join(f"ch{c}" for c in range(arr.shape[1]))] if header else []
    lines += [",".join(str(v) for v in row) for row in arr]
    path.write_text("# recorded by a test\n" + "\n".join(lines) + "\n")


def test_channel_frames_round_trip(tmp_path, recording):
    d = recording["dir"]
    ingest_recording(
        d / "layout.csv",
        d / "frames.csv",
        tmp_path / "out",
        labels_path=d / "labels.csv",
        part_labels_path=d / "parts.npy",
        baseline_path=d / "baseline.csv",
    )
    ds = open_dataset(tmp_path / "out")
    tmap = TactileMap.build(TaxelLayout.load(d / "layout.csv"))
    blob, parts, hand = recording["blob"], recording["parts"], recording["hand"]
    np.testing.assert_array_equal(ds.image[:], tmap.image(blob))
    np.testing.assert_array_equal(ds.raw[:], recording["baseline"] + blob)
    np.testing.assert_array_equal(ds.pressure_pa[:], blob)
    np.testing.assert_array_equal(ds.is_hand[:], hand)
    np.testing.assert_array_equal(ds.taxel_label[:], parts)
    for t in range(T):
        want = tmap.label_image(blob[t], parts[t]) if hand[t] else np.zeros(tmap.shape)
        np.testing.assert_array_equal(ds.label_image[t], want)
    np.testing.assert_array_equal(ds.attrs["skin_baseline_counts"], recording["baseline"])
    np.testing.assert_array_equal(ds.images_from_raw(ds.raw[:]), ds.image[:])
    assert set(ds.info["fields"]) == {
        "raw",
        "pressure_pa",
        "taxel_label",
        "image",
        "label_image",
        "is_hand",
    }


def test_taxel_frames_without_baseline(tmp_path, recording):
    d = recording["dir"]
    frames = recording["blob"].astype(np.int64) + 10
    np.save(tmp_path / "taxels.npy", frames)
    ingest_recording(d / "layout.csv", tmp_path / "taxels.npy", tmp_path / "o", counts_per_pa=2.0)
    ds = open_dataset(tmp_path / "o")
    tmap = TactileMap.build(recording["layout"])
    np.testing.assert_array_equal(ds.image[:], tmap.image(frames))
    np.testing.assert_allclose(ds.pressure_pa[:], frames / 2.0)
    assert ds.attrs["skin_counts_per_pa"] == 2.0 and "is_hand" not in ds.fields
    assert ds.active_threshold_pa == 0.0  # a recording has no generation threshold


def test_npy_and_csv_frames_give_the_same_dataset(tmp_path, recording):
    d = recording["dir"]
    a = ingest_recording(d / "layout.csv", d / "frames.csv", tmp_path / "a")
    b = ingest_recording(d / "layout.csv", d / "frames.npy", tmp_path / "b")
    assert open_dataset(a).image[:].tobytes() == open_dataset(b).image[:].tobytes()


def icub_rows(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Independent parse of an iCub file: (C, 6) calibration rows and taxel2Repr (C,)."""
    text = path.read_text()
    t2r = np.array(text.split("taxel2Repr")[1].split("(")[1].split(")")[0].split(), dtype=int)
    rows = np.loadtxt(text.split("[calibration]")[1].strip().splitlines())
    return rows, t2r


def test_real_icub_layout_with_raw_channel_frames(tmp_path, icub_positions):
    path = icub_positions / "left_forearm_V2.txt"
    rows, t2r = icub_rows(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # duplicate positions merged: documented
        layout = TaxelLayout.load(path)
    frames = np.zeros((3, len(rows)), dtype=np.int64)
    frames[0, 0] = 1000  # one channel with a unique position
    frames[1, 4] = 700  # a channel whose position repeats on other channels
    frames[2] = np.random.default_rng(3).integers(0, 3000, len(rows))
    np.save(tmp_path / "frames.npy", frames)
    with pytest.warns(UserWarning, match="merged"):
        ingest_recording(path, tmp_path / "frames.npy", tmp_path / "out")
    ds = open_dataset(tmp_path / "out")
    for t, c in ((0, 0), (1, 4)):
        same = np.flatnonzero((rows[:, :3] == rows[c, :3]).all(axis=1) & (t2r[: len(rows)] >= 0))
        p = ds.pressure_pa[t]
        pressed = np.flatnonzero(p)
        assert len(pressed) == 1
        np.testing.assert_allclose(ds.layout.positions_m[pressed[0]], rows[c, :3])
        assert p[pressed[0]] == pytest.approx(frames[t, c] / len(same))
    tmap = TactileMap.build(layout)
    np.testing.assert_array_equal(ds.image[:], tmap.image(layout.taxels_from_channels(frames)))


def _corrupt(tmp: Path, rec: dict, case: str) -> dict:
    """Input paths for one error case (files written into tmp)."""
    d, chan = rec["dir"], rec["channels"].copy()
    paths = {"layout_path": d / "layout.csv", "frames_path": d / "frames.csv"}
    bad = tmp / "bad.csv"
    if case in ("nan", "negative", "too_big", "fraction", "word"):
        value = {
            "nan": "nan",
            "negative": "-3",
            "too_big": "70000",
            "fraction": "12.5",
            "word": "abc",
        }[case]
        lines = [",".join(str(v) for v in row) for row in chan]
        cells = lines[2].split(",")
        cells[1] = value
        lines[2] = ",".join(cells)
        bad.write_text("\n".join(lines) + "\n")
        paths["frames_path"] = bad
    elif case == "width":
        np.save(tmp / "bad.npy", chan[:, :-1])
        paths["frames_path"] = tmp / "bad.npy"
    elif case == "ragged":
        bad.write_text("1,2,3\n4,5\n")
        paths["frames_path"] = bad
    elif case == "label":
        bad.write_text("hand\nnon_hand\nhand\nmaybe\nhand\nhand\n")
        paths["labels_path"] = bad
    elif case == "label_count":
        bad.write_text("1\n0\n")
        paths["labels_path"] = bad
    elif case == "part":
        parts = rec["parts"].copy()
        parts[4, 2] = 7
        np.save(tmp / "bad.npy", parts)
        paths["part_labels_path"] = tmp / "bad.npy"
    elif case == "suffix":
        paths["frames_path"] = tmp / "frames.txt"
    return paths


ERRORS = {
    "nan": r"bad.csv, line 3, column 2: frame value is nan.*Fix",
    "negative": r"bad.csv, line 3, column 2: frame value -3 is outside 0..65535.*Fix",
    "too_big": r"bad.csv, line 3, column 2: frame value 70000 is outside 0..65535",
    "fraction": r"bad.csv, line 3, column 2: frame value 12.5 is not an integer count",
    "word": r"bad.csv, line 3, column 2: frame value 'abc' is not a number.*Fix",
    "width": r"bad.npy: frame rows have 111 values; layout 'sector' needs 112 .*Fix",
    "ragged": r"bad.csv, line 2: 2 values, but the first row has 3.*Fix",
    "label": r"bad.csv, line 4: unknown class label 'maybe'; accepted: 1 or hand.*Fix",
    "label_count": r"bad.csv: class labels have shape \(2, 1\), expected \(6, 1\)",
    "part": r"bad.npy, row 4, column 3: unknown part label 7; accepted: integers 0..6.*Fix",
    "suffix": r"frames.txt: frames must be a .csv or .npy file",
}


@pytest.mark.parametrize("case", sorted(ERRORS))
def test_ingest_errors_name_file_row_and_fix(tmp_path, recording, case):
    paths = _corrupt(tmp_path, recording, case)
    out = tmp_path / "out"
    with pytest.raises(DataError, match=ERRORS[case]):
        ingest_recording(**paths, out_dir=out)
    assert not out.exists()
