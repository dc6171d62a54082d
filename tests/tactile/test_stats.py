"""`handskin stats` against hand-computed references: a small dataset whose prints are laid out
taxel by taxel, an ingested recording without the simulation's fields, and bad input refused
before any work."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import norm
from typer.testing import CliRunner

from handskin.cli import app
from tactile import TactileMap
from tactile.dataset import DatasetWriter, open_dataset
from tactile.dataset.ingest import ingest_recording
from tactile.geometry.synthetic import cylinder_sector_layout
from tactile.prints.anchors import ANCHORS
from tactile.prints.measures import bootstrap_mean, bootstrap_share, contactor_columns, read_prints
from tactile.prints.stats import MISSING, dataset_stats, stats_markdown

runner = CliRunner()
ACTIVE_PA = 500.0
ACTIONS = ["grasp", "push_away"]
# Per hand sample: pressure (Pa) of one taxel per digit (thumb, index, middle, ring, pinkie) and
# of the five palm taxels. Grasps: digits 1800, 3000, 3000, 2000, 1000 Pa -> of the four fingers
# 3/9, 3/9, 2/9, 1/9; thumb 1800 / 10800 = 1/6 of the five digits.
GRASP_PA = (1800.0, 3000.0, 3000.0, 2000.0, 1000.0, 4000.0)
PUSH_PA = (0.0, 1000.0, 1000.0, 1000.0, 1000.0, 6000.0)  # no thumb: 4 active digits' taxels
# (subject, sex, side, hand length m); hand samples cycle through them
PEOPLE = [("s0000", "male", "right", 0.17), ("s0001", "female", "left", 0.19)]
PEOPLE += [("s0002", "male", "right", 0.18)]
HANDS = [("grasp", 0), ("grasp", 1), ("grasp", 2), ("grasp", 0), ("push_away", 1)]
HANDS += [("push_away", 2)]
FORCES_N = [10.0, 20.0, 30.0, 40.0, 50.0, 60.0]


@pytest.fixture(scope="module")
def part():
    layout, _ = cylinder_sector_layout(width_mm=60, length_mm=90, pitch_mm=8)
    return layout, TactileMap.build(layout)


def taxels(layout) -> dict[str, np.ndarray]:
    """Taxels of each part, far apart on the sector (so every part is its own blob)."""
    order = np.argsort(layout.positions_m[:, 2] * 1000 + layout.positions_m[:, 0])
    n = len(order)
    digits = order[[0, n // 5, 2 * n // 5, 3 * n // 5, 4 * n // 5]]
    return {"digits": digits, "palm": order[n - 5 :]}


def hand_sample(tmap, layout, k: int) -> dict:
    action, who = HANDS[k]
    pa = GRASP_PA if action == "grasp" else PUSH_PA
    where = taxels(layout)
    p = np.zeros(tmap.n_taxels)
    labels = np.zeros(tmap.n_taxels, np.uint8)
    p[where["digits"]], labels[where["digits"]] = pa[:5], np.arange(1, 6) * (np.array(pa[:5]) > 0)
    p[where["palm"]], labels[where["palm"]] = pa[5], 6
    subject, sex, side, length = PEOPLE[who]
    desc = {"kind": "hand", "type": f"{side}_hand", "length_m": length, "subject": subject}
    return _sample(tmap, p, labels, ACTIONS.index(action), desc | {"sex": sex}, FORCES_N[k])


def object_sample(tmap, k: int) -> dict:
    p = np.zeros(tmap.n_taxels)
    p[k * 3 : k * 3 + 3] = 2000.0
    desc = {"kind": "object", "name": "sphere"}
    return _sample(tmap, p, np.zeros(tmap.n_taxels, np.uint8), -1, desc, 5.0)


def _sample(tmap, p, labels, action: int, desc: dict, force_n: float) -> dict:
    hand = desc["kind"] == "hand"
    return {
        "raw": (4000 + p).astype(np.uint16),
        "pressure_pa": p.astype(np.float32),
        "taxel_label": labels,
        "image": tmap.image(p),
        "label_image": tmap.label_image(p, labels) if hand else np.zeros(tmap.shape, np.uint8),
        "is_hand": np.uint8(hand),
        "action": np.int8(action),
        "contactor": json.dumps(desc),
        "force_n": np.float32(force_n),
    }


def write_set(folder: Path, part, samples: list[dict]) -> Path:
    """A merged dataset of ``samples`` on the test sector ``part`` (layout, map)."""
    layout, tmap = part
    w = DatasetWriter(
        folder,
        config={"episode": {"active_pa": ACTIVE_PA}},
        part="sector",
        generator_version="test-1",
        seed=3,
        tmap=tmap,
        layout=layout,
        attrs={"skin_counts_per_pa": 1.0, "skin_baseline_counts": 4000.0, "actions": ACTIONS},
    )
    w.write_chunk(0, samples)
    w.merge()
    return folder


@pytest.fixture(scope="module")
def dataset(tmp_path_factory, part) -> Path:
    layout, tmap = part
    samples = [hand_sample(tmap, layout, k) for k in range(len(HANDS))]
    objects = [object_sample(tmap, k) for k in range(2)]
    return write_set(tmp_path_factory.mktemp("stats") / "made", part, samples + objects)


@pytest.fixture(scope="module")
def recording(tmp_path_factory, part) -> Path:
    """An ingested recording: frames and hand / non-hand labels, no part labels, no force."""
    layout, _ = part
    folder = tmp_path_factory.mktemp("rec")
    layout.save(folder / "layout.npz")
    frames = np.zeros((4, layout.n_taxels))
    frames[:, :6] = 900.0
    np.save(folder / "frames.npy", frames)
    (folder / "labels.csv").write_text("label\nhand\nnon_hand\nhand\nhand\n")
    ingest_recording(
        folder / "layout.npz",
        folder / "frames.npy",
        folder / "out",
        labels_path=folder / "labels.csv",
    )
    return folder / "out"


def flood_blobs(mask: np.ndarray) -> int:
    """Slow reference: 8-connected components by an explicit flood fill."""
    seen, count = np.zeros_like(mask, bool), 0
    for start in zip(*np.nonzero(mask), strict=True):
        if seen[start]:
            continue
        count, stack = count + 1, [start]
        seen[start] = True
        while stack:
            r, c = stack.pop()
            for dr in (-1, 0, 1):
                for dc in (-1, 0, 1):
                    q = (r + dr, c + dc)
                    inside = 0 <= q[0] < mask.shape[0] and 0 <= q[1] < mask.shape[1]
                    if inside and mask[q] and not seen[q]:
                        seen[q] = True
                        stack.append(q)
    return count


def test_per_sample_prints_match_the_layout(dataset, part):
    _, tmap = part
    with open_dataset(dataset) as ds:
        prints = read_prints(ds)
        images = ds["image"][:]
    assert prints.kind.tolist() == ["hand"] * 6 + ["object"] * 2
    assert prints.action.tolist()[:6] == [a for a, _ in HANDS]
    assert prints.active.tolist() == [10, 10, 10, 10, 9, 9, 3, 3]
    assert prints.parts.tolist()[:6] == [6, 6, 6, 6, 5, 5]
    for i, image in enumerate(images):
        assert prints.area_mm2[i] == (image > 0).sum() * tmap.step_mm**2
        assert prints.blobs[i] == flood_blobs(image > 0)
    np.testing.assert_array_equal(prints.part_pressure_pa[0, 1:], (*GRASP_PA[:5], 5 * 4000.0))
    assert prints.subject.tolist()[:3] == ["s0000", "s0001", "s0002"]
    assert prints.sex.tolist()[:2] == ["male", "female"] and prints.side[1] == "left"


def test_anchored_figures_are_the_hand_computed_ones(dataset):
    values = dataset_stats(dataset).anchored
    fingers = {"index": 3 / 9, "middle": 3 / 9, "ring": 2 / 9, "pinkie": 1 / 9}
    for finger, want in fingers.items():
        assert values[f"grasp.fingers.{finger}"].value == pytest.approx(100 * want)
    assert values["grasp.digits.thumb"].value == pytest.approx(100 / 6)
    assert values["subjects.length_mean_cm"].value == pytest.approx(18.0)
    assert values["subjects.length_min_cm"].value == pytest.approx(17.0)
    assert values["subjects.length_max_cm"].value == pytest.approx(19.0)
    assert values["subjects.right_pct"].value == pytest.approx(200 / 3)
    assert values["subjects.male_pct"].value == pytest.approx(200 / 3)
    # every grasp holds the same shares: the bootstrap interval is the point
    e = values["grasp.fingers.ring"]
    assert e.low == pytest.approx(e.value) and e.high == pytest.approx(e.value) and e.n == 4


def test_groups_by_action_and_kind(dataset):
    stats = dataset_stats(dataset)
    assert list(stats.groups) == ["hand", "hand: grasp", "hand: push_away", "object"]
    assert stats.groups["hand"]["force_n"].value == pytest.approx(np.mean(FORCES_N))
    assert stats.groups["hand: push_away"]["force_n"].value == pytest.approx(55.0)
    assert stats.groups["object"]["parts"] is None  # parts per hand: not for objects
    push = stats.shares["hand: push_away"]
    # pushes: palm 5 x 6000 Pa of 5 x 6000 + 4 x 1000 Pa; no thumb touches
    assert push["pressure.palm"].value == pytest.approx(100 * 30000 / 34000)
    assert push["thumb_touch"].value == 0.0
    assert stats.shares["hand: grasp"]["thumb_touch"].value == 100.0


def test_bootstrap_interval_is_the_normal_one_for_a_large_sample():
    x = np.random.default_rng(4).normal(10.0, 2.0, 4000)
    mean, low, high = bootstrap_mean(x, seed=1)
    half = norm.ppf(0.975) * x.std() / np.sqrt(x.size)
    assert mean == pytest.approx(x.mean())
    assert (high - low) / 2 == pytest.approx(half, rel=0.1)
    share, lo, hi = bootstrap_share(np.full(50, 1.0), np.full(50, 4.0))
    assert share == lo == hi == pytest.approx(0.25)
    assert np.isnan(bootstrap_share(np.zeros(3), np.zeros(3))[0])


def test_report_side_by_side_and_the_recording_says_what_it_lacks(dataset, recording, tmp_path):
    out, png = tmp_path / "r.md", tmp_path / "s.png"
    args = ["stats", str(dataset), str(recording), "--out", str(out), "--png", str(png)]
    result = runner.invoke(app, [*args, "--no-progress"])
    assert result.exit_code == 0, result.output
    text = out.read_text()
    assert "| figure | made | out | published |" in text
    for a in ANCHORS:
        assert a.label in text and a.source in text
    rec = dataset_stats(recording)
    assert rec.groups["hand"]["force_n"] is None and rec.groups["hand"]["parts"] is None
    assert all(v is None for v in rec.anchored.values())
    assert MISSING in stats_markdown([rec])
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["{missing}"], "DATASET"),
        (["{dataset}", "{missing}"], "DATASET2"),
        (["{dataset}", "--png", "{tmp}/s.jpg"], "--png"),
        (["{dataset}", "--seed", "-1"], "--seed"),
        (["{dataset}", "--out", "{dataset}"], "--out"),
    ],
)
def test_bad_input_is_refused_before_any_work(dataset, tmp_path, args, message):
    fill = {"missing": tmp_path / "nothing", "dataset": dataset, "tmp": tmp_path}
    out = tmp_path / "r.md"
    argv = ["stats", *[a.format(**fill) for a in args]]
    argv += [] if "--out" in args else ["--out", str(out)]
    result = runner.invoke(app, argv)
    assert result.exit_code == 2, result.output
    assert message in result.output and "error:" in result.output
    assert not out.exists()


# Several contacts per sample: (contactor descriptions, contacts the instance image shows).
HAND_A = {"kind": "hand", "type": "right_hand", "subject": "s0000"}
HAND_A2 = {"kind": "hand", "type": "left_hand", "subject": "s0000"}
HAND_B = {"kind": "hand", "type": "right_hand", "subject": "s0001"}
OBJECT, BODY = {"kind": "object", "name": "sphere"}, {"kind": "body", "name": "elbow"}
MIXED = [
    ([HAND_A], 1),
    ([OBJECT], 1),
    ([HAND_A, HAND_A2], 2),
    ([HAND_A, HAND_B], 1),  # the second hand left no print
    ([OBJECT, HAND_B], 2),
    ([BODY, OBJECT], 1),
    ([BODY], 1),
]


def mixed_sample(tmap, k: int) -> dict:
    """Sample k of `MIXED`: one blob; its instance image 1 on the print, 2 on one pixel of it
    when it shows two contacts."""
    contactors, seen = MIXED[k]
    p = np.zeros(tmap.n_taxels)
    p[k * 3 : k * 3 + 3] = 2000.0
    image = tmap.image(p)
    instances = (image > 0).astype(np.uint8)
    if seen == 2:
        instances[tuple(np.argwhere(image > 0)[0])] = 2
    hand = any(c["kind"] == "hand" for c in contactors)
    pad = [-1] * (2 - len(contactors))
    subjects = [int(c["subject"][1:]) if "subject" in c else -1 for c in contactors]
    instances_id = [-1 if c["kind"] == "hand" else 10 + k for c in contactors]
    return {
        "raw": (4000 + p).astype(np.uint16),
        "pressure_pa": p.astype(np.float32),
        "image": image,
        "is_hand": np.uint8(hand),
        "contactor": json.dumps(contactors),
        "n_contacts": np.uint8(len(contactors)),
        "contact_subject": np.array(subjects + pad, np.int32),
        "contact_instance": np.array(instances_id + pad, np.int32),
        "instance_image": instances,
    }


@pytest.fixture(scope="module")
def mixed(tmp_path_factory, part) -> Path:
    layout, tmap = part
    folder = tmp_path_factory.mktemp("stats") / "mixed"
    w = DatasetWriter(
        folder,
        config={"episode": {"active_pa": ACTIVE_PA}},
        part="sector",
        generator_version="test-1",
        seed=3,
        tmap=tmap,
        layout=layout,
        attrs={"skin_counts_per_pa": 1.0, "skin_baseline_counts": 4000.0},
    )
    w.write_chunk(0, [mixed_sample(tmap, k) for k in range(len(MIXED))])
    w.merge()
    return folder


def test_samples_by_contacts_are_the_hand_counted_ones(mixed, dataset):
    groups = {(g.name, g.contacts): g for g in dataset_stats(mixed).contacts}
    # by hand from MIXED: 3 samples of one contact, 4 of two, of which 2 show one contact
    want = {
        ("all", 1): (3, 1.0, 0.0),
        ("all", 2): (4, 1.5, 50.0),
        ("hand", 1): (1, 1.0, 0.0),
        ("object", 1): (1, 1.0, 0.0),
        ("body part", 1): (1, 1.0, 0.0),
        ("hand + hand, same person", 2): (1, 2.0, 0.0),
        ("hand + hand, two people", 2): (1, 1.0, 100.0),
        ("hand + object", 2): (1, 2.0, 0.0),
        ("object + body part", 2): (1, 1.0, 100.0),
    }
    assert list(groups) == list(want)
    for key, (n, seen, fewer) in want.items():
        g = groups[key]
        assert (g.n, g.seen.value, g.fewer.value) == (n, pytest.approx(seen), pytest.approx(fewer))
        assert g.share == pytest.approx(100 * n / len(MIXED))
    text = stats_markdown([dataset_stats(mixed)])
    assert "| all | 2 | 4 | 57.1 | 1.5 [" in text
    assert "| hand + hand, two people | 2 | 1 | 14.3 | 1.0 | 100.0 |" in text
    # a dataset of one contact per sample: no section; beside a mixed one, its rows only
    plain = dataset_stats(dataset)
    assert plain.contacts is None
    assert "Several contacts at once" not in stats_markdown([plain])
    both = stats_markdown([plain, dataset_stats(mixed)])
    assert "| all | mixed | 2 | 4 |" in both and "| made |" not in both.split("Several")[1]


def test_a_sample_of_several_contacts_is_described_by_its_first_hand():
    rake = {"kind": "object", "name": "rake"}
    hand = {"kind": "hand", "subject": "s0003", "type": "left_hand", "sex": "female"}
    texts = [json.dumps([rake, hand]), json.dumps([rake, {"kind": "body", "name": "arm"}])]
    cols = contactor_columns(np.array(texts, dtype=object), np.array([1, 0]))
    assert list(cols["kind"]) == ["hand", "object"]
    assert list(cols["subject"]) == ["s0003", ""] and list(cols["side"]) == ["left", ""]
    assert list(cols["sex"]) == ["female", ""]


def box_folder(root: Path) -> Path:
    """Three 30 x 40 px prints, each a palm pad (rows 10-19, columns 5-14) in a palm box and a
    speck in no box (rows 2-3, columns 30-31); YOLO classes palm,thumb."""
    from PIL import Image

    (root / "images").mkdir(parents=True)
    (root / "labels").mkdir()
    for i in range(3):
        img = np.zeros((30, 40), np.uint8)
        img[10:20, 5:15] = 100 + 50 * i
        img[2:4, 30:32] = 90
        Image.fromarray(img).save(root / "images" / f"{i}.png")
        (root / "labels" / f"{i}.txt").write_text("0 0.25 0.5 0.3 0.4\n")  # rows 9-21, cols 4-16
    (root / "data.yaml").write_text("names: [palm, thumb]\n")
    return root


def test_sheet_lays_real_and_simulated_hand_prints_side_by_side(dataset, tmp_path):
    from tactile.cli.stats import SHEET_PRINTS, hand_tiles
    from tactile.dataset.boxes import BoxFolder
    from tactile.images.labels import CLASS_NAMES

    folder = box_folder(tmp_path / "real")
    opened = {folder: BoxFolder.open(folder)}
    real = hand_tiles(folder, "real", opened, 4)
    assert [t[2] for t in real] == ["real 0", "real 1", "real 2"]  # all three: fewer than asked
    for image, labels, _ in real:
        expected = np.zeros((30, 40), np.uint8)
        expected[10:20, 5:15] = CLASS_NAMES.index("palm")  # the speck in no box stays grey (0)
        assert image.shape == (30, 40) and np.array_equal(labels, expected)
    with open_dataset(dataset) as ds:
        hands = np.flatnonzero(ds["is_hand"][:])
        sim = hand_tiles(dataset, "made", {}, 4)
        assert len(sim) == min(len(hands), SHEET_PRINTS)
        for (image, labels, title), i in zip(sim, hands, strict=False):
            assert title == f"made #{i}"
            assert np.array_equal(image, ds[int(i)]["image"])
            assert np.array_equal(labels, ds[int(i)]["label_image"])
    sheet = tmp_path / "sheet.png"
    result = runner.invoke(app, ["stats", str(folder), str(dataset), "--sheet", str(sheet)])
    assert result.exit_code == 0, result.output
    assert sheet.read_bytes()[:4] == b"\x89PNG"
    over = runner.invoke(app, ["stats", str(folder), "--sheet", str(folder / "images" / "0.png")])
    assert over.exit_code == 2 and "--sheet" in over.output
    alone = runner.invoke(app, ["stats", str(dataset), "--sheet", str(tmp_path / "x.png")])
    assert alone.exit_code == 2 and "box folder" in alone.output


def test_sheet_without_hand_prints_is_refused_before_any_output(part, tmp_path):
    objects = write_set(tmp_path / "objects", part, [object_sample(part[1], k) for k in range(2)])
    folder, report = box_folder(tmp_path / "real"), tmp_path / "shapes.md"
    args = ["stats", str(folder), str(objects), "--out", str(report)]
    result = runner.invoke(app, [*args, "--sheet", str(tmp_path / "sheet.png")])
    assert result.exit_code == 2 and "no hand print" in result.output
    assert not report.exists() and not (tmp_path / "sheet.png").exists()
