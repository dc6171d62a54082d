"""Real box-labelled prints (`tactile.dataset.boxes`) and the shape statistics of prints
(`tactile.prints.shapes`), against folders drawn here with known boxes and pixels, the expected
labels and statistics counted by hand; and against the real_hands folds where present."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from scipy import ndimage

from tactile.dataset.boxes import (
    PAPER_PIXEL_MM,
    BoxFolder,
    box_labels,
    box_members,
    ingest_boxes,
    is_box_folder,
    parse_frame,
)
from tactile.errors import DataError
from tactile.images.labels import CLASS_NAMES, IGNORE
from tactile.prints.shapes import (
    boxes_of_labels,
    folder_shapes,
    part_layout,
    print_shape,
    quartiles,
    without_palm,
)

PALM, THUMB, INDEX = (CLASS_NAMES.index(n) for n in ("palm", "thumb", "index"))
ORDER = ["palm", "thumb", "index", "middle", "ring", "pinkie"]  # the real_hands files' order


def drawn_print() -> tuple[np.ndarray, list[str]]:
    """A 40 x 60 px print: a palm pad (rows 20-34, columns 10-29: 300 px at 200), a thumb blob
    (rows 5-9, columns 40-49: 50 px) apart from it, an index blob (rows 2-7, columns 10-19: 60 px)
    touching nothing, a 4-px speck at level 3 (residue) and a 6-px blob at 90 in no box; and its
    YOLO lines (classes in `ORDER`): the palm box rows 18-36, columns 8-32; the thumb box rows
    4-10, columns 38-52; the index box rows 0-10, columns 8-22 overlapping the palm box nowhere."""
    img = np.zeros((40, 60), np.uint8)
    img[20:35, 10:30] = 200
    img[5:10, 40:50] = 150
    img[2:8, 10:20] = 120
    img[38:40, 0:2] = 3
    img[30:32, 50:53] = 90

    def yolo(c, r0, r1, c0, c1):
        return f"{c} {(c0 + c1) / 2 / 60} {(r0 + r1) / 2 / 40} {(c1 - c0) / 60} {(r1 - r0) / 40}"

    lines = [yolo(0, 18, 36, 8, 32), yolo(1, 4, 10, 38, 52), yolo(2, 0, 10, 8, 22)]
    return img, lines


def write_folder(root: Path, prints, stretch: int | None = None, yaml: str | None = None) -> Path:
    (root / "images").mkdir(parents=True)
    (root / "labels").mkdir()
    for i, (img, lines) in enumerate(prints):
        im = Image.fromarray(img)
        if stretch:
            im = im.resize((stretch, stretch), Image.Resampling.NEAREST)
        im.save(root / "images" / f"{i}.png")
        (root / "labels" / f"{i}.txt").write_text("\n".join(lines) + "\n")
    if yaml is not None:
        (root / "data.yaml").write_text(yaml)
    return root


def test_reader_takes_boxes_to_pixels_and_names_to_parts(tmp_path):
    img, lines = drawn_print()
    root = write_folder(tmp_path / "f", [(img, lines)])
    assert is_box_folder(root) and not is_box_folder(tmp_path)
    folder = BoxFolder.open(root, ORDER)
    p = folder[0]
    assert np.array_equal(p.image, img)
    assert p.boxes.tolist() == [
        [PALM, 18, 36, 8, 32],
        [THUMB, 4, 10, 38, 52],
        [INDEX, 0, 10, 8, 22],
    ]
    assert (
        BoxFolder.open(
            write_folder(tmp_path / "y", [(img, lines)], yaml="names: [palm, thumb, index]\n")
        )[0].boxes.tolist()
        == p.boxes.tolist()
    )
    aliases = BoxFolder.open(root, ["Palm", "thumb", "index", "middle", "ring", "little"])
    assert aliases.part_ids.tolist() == [6, 1, 2, 3, 4, 5]


def test_a_stretched_image_is_resized_back_with_its_boxes(tmp_path):
    img, lines = drawn_print()
    root = write_folder(tmp_path / "f", [(img, lines)], stretch=80)
    p = BoxFolder.open(root, ORDER, frame_px=(40, 60))[0]
    assert p.image.shape == (40, 60)
    assert p.boxes.tolist()[0] == [PALM, 18, 36, 8, 32]  # normalised boxes hold in any frame
    # bilinear resampling changes the levels one pixel around each edge, nothing else
    near = ndimage.binary_dilation(img > 0, iterations=2) & ~ndimage.binary_erosion(
        img > 0, iterations=2
    )
    assert np.array_equal(p.image[~near], img[~near])


def test_box_labels_follow_the_smallest_box_rule():
    img, _ = drawn_print()
    boxes = np.array([[PALM, 18, 36, 8, 32], [INDEX, 25, 30, 12, 16], [THUMB, 4, 10, 38, 52]])
    labels = box_labels(img, boxes)
    assert (labels[25:30, 12:16] == INDEX).all()  # inside the palm box and the smaller one
    assert (labels == INDEX).sum() == 20 and (labels == PALM).sum() == 300 - 20
    assert (labels == THUMB).sum() == 50
    assert (labels[2:8, 10:20] == IGNORE).all()  # contact in no box
    assert (labels[30:32, 50:53] == IGNORE).all() and (labels[38:40, 0:2] == IGNORE).all()
    assert (labels[img == 0] == 0).all()
    members = box_members(img, boxes)
    assert (
        (members == 1).sum() == 20
        and (members == 0).sum() == 280
        and (members == -1).sum() == img.size - 350
    )


def test_print_shape_counted_by_hand():
    img, _ = drawn_print()
    folder_boxes = np.array([[PALM, 18, 36, 8, 32], [THUMB, 4, 10, 38, 52], [INDEX, 0, 10, 8, 22]])
    s = print_shape(img, folder_boxes)
    # blobs of >= 30 px above level 4: palm 300, thumb 50, index 60 (the 6-px blob is a speck)
    assert s["blobs"] == 3 and s["area_mm2"] == 410
    assert s["span_mm"] == 40  # rows 2..34 (33), columns 10..49 (40)
    assert s["rows_mm"] == 33 and s["cols_mm"] == 40
    assert s["parts"] == 3
    assert s["finger_blobs"] == 1.0  # thumb and index each alone in a blob
    assert s["palm_share"] == pytest.approx(300 / 410)
    fused = img.copy()
    fused[8:20, 12:16] = 100  # a bridge joins the index blob to the palm
    s = print_shape(fused, folder_boxes)
    assert s["blobs"] == 2 and s["finger_blobs"] == 0.5  # the index shares its blob now
    assert print_shape(img, folder_boxes, step_mm=2.0)["area_mm2"] == 4 * 410
    assert print_shape(img.T.copy(), folder_boxes[:, [0, 3, 4, 1, 2]])["rows_mm"] == 40


def test_part_layout_measured_by_hand():
    middle, pinkie = CLASS_NAMES.index("middle"), CLASS_NAMES.index("pinkie")
    boxes = np.array(
        [
            [PALM, 0, 10, 0, 10],  # centre (5, 5)
            [THUMB, 0, 10, 30, 40],  # (5, 35): 30 from the palm
            [THUMB, 0, 2, 100, 102],  # a second, smaller thumb box: not the thumb's centre
            [INDEX, 40, 50, 0, 10],  # (45, 5): 40
            [middle, 50, 60, 0, 10],  # (55, 5): 50, 10 from the index
            [pinkie, 70, 80, 0, 10],  # (75, 5): 70, 30 from the index; the ring is missing
        ]
    )
    d = part_layout(boxes)
    assert d["palm_thumb_mm"] == 30 and d["index_pinkie_mm"] == 30
    assert d["palm_finger_mm"] == pytest.approx((40 + 50 + 70) / 3)
    assert d["neighbour_mm"] == 10  # index-middle; middle-ring and ring-pinkie lack the ring
    assert part_layout(boxes, step_mm=2.0)["palm_thumb_mm"] == 60
    # fingers below the palm (rows down) and the thumb to its right: turned up, a left hand
    assert d["thumb_right"] == 0.0
    up = boxes.copy()
    up[:, 1:3] = 80 - up[:, 2:0:-1]  # mirrored top to bottom: fingers up, thumb still right
    assert part_layout(up)["thumb_right"] == 1.0
    assert d["little_along"] == 0.0  # index to little runs down the rows
    across = boxes.copy()
    across[:, 1:5] = boxes[:, [3, 4, 1, 2]]  # transposed: index to little along +columns
    assert part_layout(across)["little_along"] == 1.0
    assert part_layout(across[:, [0, 1, 2, 4, 3]] * [1, 1, 1, -1, -1])["little_along"] == 0.0
    alone = part_layout(boxes[:1])
    assert all(np.isnan(v) for v in alone.values())


def test_where_the_fingers_point_reads_alike_for_either_hand():
    """The direction from the palm's centre to the fingers', degrees from +rows towards +columns;
    a left-drawn hand is mirrored across the rows so that a hand and its mirror read alike."""
    right = np.array(
        [
            [PALM, 40, 60, 40, 60],  # centre (50, 50)
            [INDEX, 75, 85, 15, 25],  # (80, 20): fingers down and to the left, -45 deg
            [THUMB, 15, 25, 15, 25],  # (20, 20): up and left, right of the fingers
        ]
    )
    d = part_layout(right)
    assert d["thumb_right"] == 1.0 and d["fingers_deg"] == pytest.approx(-45.0)
    left = right.copy()
    left[:, 1:3] = 100 - right[:, 2:0:-1]  # mirrored top to bottom: fingers up, a left hand
    d = part_layout(left)
    assert d["thumb_right"] == 0.0 and d["fingers_deg"] == pytest.approx(-45.0)
    assert np.isnan(part_layout(right[:2])["fingers_deg"])  # no thumb: chirality unknown


def test_simulated_prints_are_boxed_tightly_around_each_part():
    img, _ = drawn_print()
    labels = np.zeros_like(img)
    labels[20:35, 10:30], labels[5:10, 40:50], labels[2:8, 10:20] = PALM, THUMB, INDEX
    labels[30:32, 50:53] = INDEX  # too few pixels of its blob: a speck, not part of the box
    boxes = boxes_of_labels(labels, img)
    assert boxes.tolist() == [[THUMB, 5, 10, 40, 50], [INDEX, 2, 8, 10, 20], [PALM, 20, 35, 10, 30]]


def test_ingest_writes_a_folder_that_describes_itself(tmp_path):
    img, lines = drawn_print()
    src = write_folder(tmp_path / "src", [(img, lines), (img[::-1].copy(), lines)], stretch=80)
    out = ingest_boxes(src, tmp_path / "out", ORDER, (40, 60))
    again = BoxFolder.open(out)  # no flags: data.yaml holds the names and the frame
    first = BoxFolder.open(src, ORDER, (40, 60))
    assert len(again) == 2 and again.frame_px == (40, 60)
    for i in range(2):
        assert np.array_equal(again[i].image, first[i].image)
        assert np.array_equal(again[i].boxes, first[i].boxes)
    assert "labels_from: boxes" in (out / "data.yaml").read_text()
    with pytest.raises(DataError, match="not a new or empty folder"):
        ingest_boxes(src, out, ORDER, (40, 60))


@pytest.mark.parametrize(
    ("change", "words"),
    [
        ({"classes": ["palm", "wrist"]}, "class 'wrist' is no hand part"),
        ({"classes": None}, "no data.yaml names the box classes"),
        ({"line": "7 0.5 0.5 0.1 0.1"}, r"line 1: class 7 of 6 named classes"),
        ({"line": "0 0.5 0.5"}, r"line 1: '0 0.5 0.5' is not 'class cx cy w h'"),
        ({"line": "0 0.5 1.5 0.1 0.1"}, "a box outside"),
        ({"drop_label": True}, "no label file for"),
    ],
)
def test_bad_folders_are_named(tmp_path, change, words):
    img, lines = drawn_print()
    if "line" in change:
        lines = [change["line"]]
    root = write_folder(tmp_path / "f", [(img, lines)])
    if change.get("drop_label"):
        (root / "labels" / "0.txt").unlink()
        (root / "labels" / "x.txt").write_text("")
    with pytest.raises(DataError, match=words):
        BoxFolder.open(root, change.get("classes", ORDER))[0]


def test_frame_flag():
    assert parse_frame("247x362") == (247, 362) and parse_frame(None) is None
    with pytest.raises(DataError, match="give ROWSxCOLUMNS"):
        parse_frame("247")


@pytest.fixture(scope="module")
def real_fold(shared_data):
    path = shared_data / "real_hands" / "fold1"
    if not path.is_dir():
        pytest.skip(f"real hand prints not found at {path}")
    return BoxFolder.open(path, ORDER, (247, 362))


def test_the_real_fold_reads_as_its_readme_says(real_fold):
    """342 prints, 247 x 362 at 1 mm; 91 % of images have five or six parts boxed."""
    assert len(real_fold) == 342
    parts = [len(set(real_fold[i].boxes[:, 0].tolist())) for i in range(len(real_fold))]
    assert real_fold[0].image.shape == (247, 362)
    assert 0.88 <= np.mean(np.array(parts) >= 5) <= 0.94


def test_the_share_without_a_palm_counts_the_prints_with_no_palm_box(real_fold):
    """`without_palm` reads the boxed pixels; counted from the label files instead: the prints
    with no palm box (fold 1: 106 of 342)."""
    no_box = np.mean([PALM not in real_fold[i].boxes[:, 0] for i in range(len(real_fold))])
    assert without_palm(folder_shapes(real_fold)) == pytest.approx(no_box, abs=2 / len(real_fold))
    assert 0.25 <= no_box <= 0.37


def test_real_prints_are_drawn_as_right_hands_in_the_papers_share(real_fold):
    """77.8 % of the paper's people were right-handed; the share of real prints whose thumb lies
    right of the fingers (rows down, fingers up) is that, within 3 binomial sd (fold 1: 0.78)."""
    s = folder_shapes(real_fold)
    right = s.values["thumb_right"][np.isfinite(s.values["thumb_right"])]
    sd = np.sqrt(0.778 * 0.222 / len(right))
    assert abs(right.mean() - 0.778) < 3 * sd, f"{right.mean():.3f} of {len(right)}"


def test_real_prints_break_into_marks(real_fold):
    """The published description of the folds: prints wrap the forearm (a span near the map's
    width), broken into several marks, most fingers apart from the palm."""
    s = folder_shapes(real_fold)
    assert quartiles(s.values["blobs"])[1] >= 4
    assert 200 <= quartiles(s.values["span_mm"])[1] <= 247
    assert quartiles(s.values["finger_blobs"])[1] >= 0.4


def test_stats_reads_a_box_folder_at_the_step_given(tmp_path):
    """`handskin stats --box-step-mm`: mm of skin a pixel of a box folder (the paper's images:
    `PAPER_PIXEL_MM` by default); out of range, refused before any output."""
    from typer.testing import CliRunner

    from handskin.cli import app

    root = write_folder(tmp_path / "f", [drawn_print()], yaml=f"names: {ORDER}\n")
    runner, spans = CliRunner(), {}
    for step in ("1", "2", None):
        args = ["stats", str(root)] + ([] if step is None else ["--box-step-mm", step])
        result = runner.invoke(app, args)
        assert result.exit_code == 0, result.output
        line = next(x for x in result.output.splitlines() if x.startswith("span of the print"))
        spans[step] = float(line.rsplit(" ", 1)[1])
    assert spans["1"] == 40 and spans["2"] == 80 and spans[None] == round(40 * PAPER_PIXEL_MM)
    out = tmp_path / "r.md"
    bad = runner.invoke(app, ["stats", str(root), "--box-step-mm", "0", "--out", str(out)])
    assert bad.exit_code == 2 and "--box-step-mm" in bad.output and not out.exists()
