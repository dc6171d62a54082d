"""TaxelLayout and its file formats, checked against real iCub files and independent references.

References: ``positions_summary.csv`` (counts computed independently of handskin) and the
per-channel conversions ``csv/<file>_taxels.csv`` (triangle, pad, taxel2Repr, x/y/z in mm,
has_position), both in ../shared/data/icub_skin; small hand-written files with known answers.
"""

from __future__ import annotations

import csv
import warnings
from pathlib import Path

import numpy as np
import pytest

from tactile.errors import LayoutError, MapError
from tactile.geometry.layout import TaxelLayout
from tactile.geometry.synthetic import cylinder_sector_layout

SUMMARY_FILES = [
    "left_arm",
    "left_arm_mesh",
    "left_foot",
    "left_forearm_V2",
    "left_forearm_mesh",
    "left_forearm_nomesh",
    "left_hand_V2_1",
    "left_leg_lower",
    "left_leg_upper",
    "right_arm",
    "right_forearm_V2",
    "right_forearm_mesh",
    "right_leg_upper",
    "torso",
]


def summary(icub_positions: Path) -> dict[str, dict[str, str]]:
    with open(icub_positions.parent / "positions_summary.csv", newline="") as fh:
        return {row["file"].removesuffix(".txt"): row for row in csv.DictReader(fh)}


def reference_channels(icub_positions: Path, stem: str) -> list[dict[str, str]]:
    """Pressure-taxel channels from the independent conversion: a position, taxel2Repr not -1/-2."""
    with open(icub_positions.parent / "csv" / f"{stem}_taxels.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    return [r for r in rows if r["has_position"] == "1" and r["taxel2Repr"] not in ("-1", "-2")]


def load_quietly(path: Path) -> TaxelLayout:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return TaxelLayout.load(path)


def all_channels(layout: TaxelLayout) -> np.ndarray:
    return np.sort(np.concatenate([layout.channel_ids, layout.merged_channels[:, 0]]))


# ---- real iCub files ----------------------------------------------------------------------------


@pytest.mark.parametrize("stem", SUMMARY_FILES)
def test_icub_channels_and_counts_match_independent_conversion(icub_positions, stem):
    layout = load_quietly(icub_positions / f"{stem}.txt")
    ref = reference_channels(icub_positions, stem)
    assert layout.n_channels == int(summary(icub_positions)[stem]["rows"])
    np.testing.assert_array_equal(all_channels(layout), sorted(int(r["index"]) for r in ref))
    distinct_mm = {(r["x_mm"], r["y_mm"], r["z_mm"]) for r in ref}
    assert layout.n_taxels == len(distinct_mm)
    triangle = {int(r["index"]): int(r["triangle"]) for r in ref}
    assert [triangle[c] for c in layout.channel_ids] == layout.module_ids.tolist()


@pytest.mark.parametrize("stem", ["left_arm", "left_forearm_mesh", "left_leg_upper"])
def test_icub_files_without_duplicates_keep_every_positioned_row_silently(icub_positions, stem):
    row = summary(icub_positions)[stem]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        layout = TaxelLayout.load(icub_positions / f"{stem}.txt")
    assert layout.n_taxels == int(row["rows_with_position"]) == int(row["unique_positions"])
    assert layout.merged_channels.shape == (0, 2)


def test_forearm_v2_duplicates_are_merged_with_one_warning(icub_positions):
    row = summary(icub_positions)["left_forearm_V2"]
    n_dup = int(row["rows_with_position"]) - int(row["unique_positions"])  # 240 - 148
    with pytest.warns(UserWarning, match=rf"left_forearm_V2\.txt: {n_dup} channels") as record:
        layout = TaxelLayout.load(icub_positions / "left_forearm_V2.txt")
    assert len(record) == 1
    assert layout.n_taxels == int(row["unique_positions"]) == 148
    assert len(layout.merged_channels) == n_dup


def test_torso_excludes_thermal_pads(icub_positions):
    row = summary(icub_positions)["torso"]
    with pytest.warns(UserWarning, match="torso"):
        layout = TaxelLayout.load(icub_positions / "torso.txt")
    tactile = int(row["rows_with_position"]) - int(row["thermal_t2r_eq_-2"])
    assert all_channels(layout).size == tactile == int(row["tactile_taxels_t2r_ge0"]) == 440
    assert np.all(np.isin(layout.channel_ids % 12, [6, 10], invert=True))


def test_palm_drops_the_four_positioned_dummy_channels(icub_positions):
    layout = TaxelLayout.load(icub_positions / "left_hand_V2_1.txt")
    assert int(summary(icub_positions)["left_hand_V2_1"]["rows_with_position"]) == 48
    assert layout.n_taxels == 44


def test_channel_frame_maps_to_the_file_rows(icub_positions):
    path = icub_positions / "left_forearm_V2.txt"
    layout = load_quietly(path)
    lines = path.read_text().splitlines()
    first_row = lines.index("[calibration]") + 1
    file_rows = np.array([lines[first_row + c].split() for c in range(384)], dtype=float)
    np.testing.assert_array_equal(layout.positions_m, file_rows[layout.channel_ids, :3])
    groups: dict[tuple[float, ...], list[int]] = {}
    for c in np.flatnonzero(np.any(file_rows != 0, axis=1)):
        groups.setdefault(tuple(file_rows[c, :3]), []).append(int(c))
    expected = [np.mean(groups[tuple(p)]) for p in layout.positions_m]
    frame = np.arange(384, dtype=float)
    np.testing.assert_allclose(layout.taxels_from_channels(frame), expected)
    batch = layout.taxels_from_channels(np.stack([frame, 2 * frame, np.zeros(384)]))
    np.testing.assert_allclose(batch, [expected, 2 * np.array(expected), np.zeros(148)])


def test_icub_normals_are_unit_and_parallel_to_the_file(icub_positions):
    layout = TaxelLayout.load(icub_positions / "left_forearm_mesh.txt")  # |n| 0.6-1 in the file
    ref = {int(r["index"]): r for r in reference_channels(icub_positions, "left_forearm_mesh")}
    raw = np.array([[float(ref[c][k]) for k in ("nx", "ny", "nz")] for c in layout.channel_ids])
    np.testing.assert_allclose(np.linalg.norm(layout.normals, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.cross(layout.normals, raw), 0.0, atol=1e-12)
    assert TaxelLayout.load(icub_positions / "left_forearm_nomesh.txt").normals is None


# ---- round trips and the project's formats ------------------------------------------------------


def assert_same_layout(a: TaxelLayout, b: TaxelLayout) -> None:
    for key in ("positions_m", "normals", "module_ids", "channel_ids", "merged_channels"):
        x, y = getattr(a, key), getattr(b, key)
        assert (x is None) == (y is None), key
        if x is not None:
            np.testing.assert_array_equal(x, y, err_msg=key)
    assert (a.n_channels, a.name) == (b.n_channels, b.name)


@pytest.mark.parametrize("suffix", [".npz", ".csv"])
def test_round_trip_real_layout(icub_positions, tmp_path, suffix):
    layout = load_quietly(icub_positions / "left_forearm_V2.txt")
    layout.save(tmp_path / f"v2{suffix}")
    assert_same_layout(layout, TaxelLayout.load(tmp_path / f"v2{suffix}"))


@pytest.mark.parametrize("suffix", [".npz", ".csv"])
def test_round_trip_synthetic_layout_without_ids(tmp_path, suffix):
    layout, _ = cylinder_sector_layout(pitch_mm=30.0, noise_m=1e-4, name="cyl, odd: name")
    layout.save(tmp_path / f"cyl{suffix}")
    assert_same_layout(layout, TaxelLayout.load(tmp_path / f"cyl{suffix}"))


def test_hand_written_csv_in_mm_with_merged_channels(tmp_path):
    path = tmp_path / "patch.csv"
    path.write_text(
        "# handskin taxel layout v1\n# name: patch\n# n_channels: 6\n"
        "x_mm,y_mm,z_mm,module,channel,merged_channels\n"
        "0,0,0,0,0,\n10,0,0,0,1,3 5\n0,10,0,1,2,4\n"
    )
    layout = TaxelLayout.load(path)
    np.testing.assert_allclose(layout.positions_m, [[0, 0, 0], [0.01, 0, 0], [0, 0.01, 0]])
    assert (layout.name, layout.n_channels, layout.normals) == ("patch", 6, None)
    frame = np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    np.testing.assert_allclose(layout.taxels_from_channels(frame), [1.0, 4.0, 4.0])


@pytest.mark.parametrize(("units", "scale"), [("m", 1.0), ("mm", 1e-3)])
def test_plain_columns_and_plain_xyz_need_units(tmp_path, units, scale):
    pts = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 2.0, 0.5]])
    (tmp_path / "plain.csv").write_text("x,y,z\n" + "\n".join(",".join(map(str, p)) for p in pts))
    (tmp_path / "plain.txt").write_text("# x y z\n" + "\n".join(" ".join(map(str, p)) for p in pts))
    for name in ("plain.csv", "plain.txt"):
        with pytest.raises(LayoutError, match=r"--units m or mm; in Python units='m' or 'mm'"):
            TaxelLayout.load(tmp_path / name)
        layout = TaxelLayout.load(tmp_path / name, units=units)
        np.testing.assert_allclose(layout.positions_m, pts * scale)


def test_unknown_csv_unit_names_accepted_units_and_fix(tmp_path):
    path = tmp_path / "inch.csv"
    path.write_text("x_in,y_in,z_in\n0,0,0\n1,0,0\n0,1,0\n")
    with pytest.raises(LayoutError, match=r"inch\.csv, line 1: .*'in'; accepted units: m, mm"):
        TaxelLayout.load(path)


# ---- subset -------------------------------------------------------------------------------------


def test_subset_keeps_ids_normals_and_merged_channels(icub_positions):
    layout = load_quietly(icub_positions / "left_forearm_V2.txt")
    keep = np.arange(0, 148, 3)
    sub = layout.subset(keep)
    np.testing.assert_array_equal(sub.positions_m, layout.positions_m[keep])
    np.testing.assert_array_equal(sub.normals, layout.normals[keep])
    np.testing.assert_array_equal(sub.channel_ids, layout.channel_ids[keep])
    np.testing.assert_array_equal(sub.module_ids, layout.module_ids[keep])
    kept_merged = np.isin(layout.merged_channels[:, 1], keep)
    assert sorted(sub.merged_channels[:, 0]) == sorted(layout.merged_channels[kept_merged, 0])
    frame = np.random.default_rng(0).uniform(0, 255, 384)
    full = layout.taxels_from_channels(frame)
    np.testing.assert_allclose(sub.taxels_from_channels(frame), full[keep])


@pytest.mark.parametrize(
    "keep", [[2, 1, 3], [1, 1, 2], [0, 1, 999], [-1, 0, 1], np.ones(148, dtype=bool)]
)
def test_subset_rejects_unsorted_duplicate_out_of_range_and_masks(icub_positions, keep):
    layout = load_quietly(icub_positions / "left_forearm_V2.txt")
    with pytest.raises(LayoutError, match="keep"):
        layout.subset(np.asarray(keep))


# ---- validation of arrays -----------------------------------------------------------------------

TRIANGLE = np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.0, 0.01, 0.0]])


def test_arrays_are_copied_read_only_and_near_unit_normals_normalised():
    pos = TRIANGLE.copy()
    layout = TaxelLayout(pos, normals=[[0, 0, 1.0005]] * 3, module_ids=[0.0, 0.0, 1.0])
    pos[0, 0] = 5.0
    assert layout.positions_m[0, 0] == 0.0 and not layout.positions_m.flags.writeable
    np.testing.assert_allclose(layout.normals, [[0, 0, 1]] * 3, atol=0)
    assert layout.module_ids.dtype == np.int64


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"positions_m": [[0, 0, 0], [1, 0, 0], [0, np.nan, 0]]}, "positions_m row 2"),
        ({"positions_m": TRIANGLE[:2]}, "at least 3"),
        ({"positions_m": [[0, 0, 0], [1, 1, 1], [2, 2, 2.0]]}, "one line"),
        ({"positions_m": TRIANGLE[:, :2]}, r"expected \(N, 3\)"),
        ({"positions_m": TRIANGLE, "normals": [[0, 0, 1], [0, 0, 2], [0, 0, 1]]}, "normals row 1"),
        ({"positions_m": TRIANGLE, "module_ids": [0, 1]}, "module_ids has shape"),
        ({"positions_m": TRIANGLE, "channel_ids": [0, 1, 1]}, "channel 1 is assigned"),
        ({"positions_m": TRIANGLE, "channel_ids": [0, 1, 2], "n_channels": 2}, "n_channels=2"),
        ({"positions_m": TRIANGLE, "merged_channels": [[3, 0]]}, "without channel_ids"),
    ],
)
def test_invalid_arrays_are_rejected(kwargs, match):
    with pytest.raises(LayoutError, match=match):
        TaxelLayout(**kwargs)


def test_taxels_from_channels_rejects_bad_frames(icub_positions):
    layout = load_quietly(icub_positions / "left_forearm_V2.txt")
    with pytest.raises(MapError, match=r"\(384,\)"):
        layout.taxels_from_channels(np.zeros(383))
    with pytest.raises(MapError, match="NaN"):
        layout.taxels_from_channels(np.full((2, 384), np.nan))
    with pytest.raises(LayoutError, match="no channel ids"):
        TaxelLayout(TRIANGLE).taxels_from_channels(np.zeros(3))


# ---- malformed files ----------------------------------------------------------------------------

ICUB_HEAD = "name\tpatch\nspatial_sampling\ttaxel\ntaxel2Repr ( 0 0 0 -2 )\n"
THREE_ROWS = "0.0 0.0 0.0 0 0 0\n0.01 0.0 0.0 0 0 1\n0.0 0.01 0.0 0 0 1\n"  # 1st row: absent
GOOD_ROWS = THREE_ROWS + "0.01 0.01 0.0 0 0 1\n"  # 4th row: thermal (taxel2Repr -2)
CAL = ICUB_HEAD + "[calibration]\n"


@pytest.mark.parametrize(
    ("text", "match"),
    [
        (ICUB_HEAD + GOOD_ROWS, r"lines 1-7: no '\[calibration\]' line. Fix"),
        (CAL + GOOD_ROWS + "0 0 1 0 0\n", r"line 9: 5 values, expected 6"),
        (CAL + "0.0 abc 0 0 0 1\n" + GOOD_ROWS, r"line 5: 'abc' is not a number"),
        (CAL + GOOD_ROWS + "nan 0 0 0 0 1\n", r"line 9: NaN or inf"),
        (CAL + THREE_ROWS, "at least 3 taxels"),
        ("name x\n[calibration]\n1 0 0 0 0 1\n2 0 0 0 0 1\n3 0 0 0 0 1\n", "one line"),
        ("name x\ntaxel2Repr ( 0 a 1 )\n[calibration]\n" + GOOD_ROWS, r"line 2: taxel2Repr must"),
    ],
)
def test_malformed_icub_files_name_file_line_and_problem(tmp_path, text, match):
    path = tmp_path / "bad_icub.txt"
    path.write_text(text)
    with pytest.raises(LayoutError, match=r"bad_icub\.txt") as err:
        TaxelLayout.load(path)
    assert err.match(match)


def test_icub_thermal_pad_excluded_and_rows_beyond_taxel2repr_kept(tmp_path):
    path = tmp_path / "tiny.txt"  # taxel2Repr covers 4 rows: row 3 is thermal, row 4 has no entry
    path.write_text(CAL + GOOD_ROWS + "0.02 0.0 0.0 0 0 1\n")
    layout = TaxelLayout.load(path)
    assert layout.channel_ids.tolist() == [1, 2, 4] and layout.n_channels == 5
    np.testing.assert_allclose(layout.positions_m[2], [0.02, 0, 0])


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("x_m,y_m,z_m\n0,0,0\n1,0\n0,1,0\n", r"line 3: 2 values, expected 3"),
        ("# note\nx_m,y_m,z_m\n0,0,0\n1,0,0\n0,inf,0\n", r"line 5: NaN or inf"),
        ("x_m,y_m,z_m,colour\n0,0,0,red\n", r"unknown columns \['colour'\]"),
        ("# handskin taxel layout v9\nx_m,y_m,z_m\n", r"line 1: layout CSV v9"),
    ],
)
def test_malformed_csv_files_name_file_and_line(tmp_path, text, match):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(LayoutError, match=r"bad\.csv") as err:
        TaxelLayout.load(path)
    assert err.match(match)


def test_unknown_suffixes_are_rejected(tmp_path):
    with pytest.raises(LayoutError, match=r"'\.ply'.*\.npz, \.csv, \.txt"):
        TaxelLayout.load(tmp_path / "layout.ply")
    with pytest.raises(LayoutError, match=r"'\.json'; use \.npz or \.csv"):
        TaxelLayout(TRIANGLE).save(tmp_path / "layout.json")
    assert list(tmp_path.iterdir()) == []


def test_failed_save_leaves_the_previous_file_intact(tmp_path, monkeypatch):
    TaxelLayout(TRIANGLE, name="good").save(tmp_path / "out.csv")
    TaxelLayout(TRIANGLE, name="good").save(tmp_path / "out.npz")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    with pytest.raises(LayoutError, match="line break"):
        TaxelLayout(TRIANGLE * 2, name="two\nlines").save(tmp_path / "out.csv")

    def broken_savez(fh, **arrays):
        fh.write(b"partial")
        raise OSError("disk full")

    monkeypatch.setattr(np, "savez", broken_savez)
    with pytest.raises(OSError, match="disk full"):
        TaxelLayout(TRIANGLE * 2).save(tmp_path / "out.npz")
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before
