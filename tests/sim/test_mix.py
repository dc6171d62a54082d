"""Samples of several contacts (`sim.generate.mix`): generated end to end on the small plate,
checked against what each sample's own fields say (its contactor list, its labels, the split), and
against the single-contact generator they extend."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest

from sim.generate.config import GenerateConfig
from sim.generate.run import generate
from tactile.config import override
from tactile.dataset import open_dataset
from tactile.errors import ConfigError

MIX = {
    "part": "plate",
    "n": 16,
    "chunk_size": 4,
    "n_subjects": 4,
    "instances_per_kind": 3,
    "duration_scale": 0.5,
    "split": "keyed",
    "episode.max_attempts": 20,
    "mix.fraction": 0.75,
    "mix.min_gap_mm": 60.0,
}


def config(**kw: object):
    """The mixing configuration with dotted-key changes (as a TOML file would give them)."""
    return override(GenerateConfig(), MIX | kw)


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def mixed(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("mix") / "ds"
    generate(config(), out, workers=1, progress=False)
    return out


def test_two_contact_samples_carry_both_contactors(mixed: Path) -> None:
    with open_dataset(mixed) as ds:
        n = ds["n_contacts"][:]
        described = [json.loads(c) for c in ds["contactor"][:]]
        subjects, instances = ds["contact_subject"][:], ds["contact_instance"][:]
        is_hand = ds["is_hand"][:]
    assert set(n.tolist()) == {1, 2}
    for k, desc in enumerate(described):
        assert isinstance(desc, list) and len(desc) == n[k]
        hands = [d["kind"] == "hand" for d in desc]
        assert is_hand[k] == any(hands)
        for j in range(len(desc)):  # a hand has a person and no instance; others the reverse
            assert (subjects[k, j] >= 0) == hands[j] and (instances[k, j] >= 0) != hands[j]
        assert (subjects[k, len(desc) :] == -1).all() and (instances[k, len(desc) :] == -1).all()


def test_hand_parts_lie_on_hand_contacts_and_pixels_on_pressed_contacts(mixed: Path) -> None:
    """A taxel labelled with a hand part belongs to a contact that is a hand; a pixel's contact
    is one the sample has, and only where the tactile image is lit."""
    with open_dataset(mixed) as ds:
        for k in range(len(ds)):
            s = ds[k]
            desc = json.loads(s["contactor"])
            owner = s["taxel_contactor"][s["taxel_label"] > 0]
            assert all(desc[j]["kind"] == "hand" for j in owner.tolist())
            pixels = s["instance_image"]
            assert pixels.max() <= len(desc)
            assert not (pixels[s["image"] == 0]).any()


def test_no_person_or_object_on_both_sides_of_the_split(mixed: Path) -> None:
    with open_dataset(mixed) as ds:
        subjects, instances = ds["contact_subject"][:], ds["contact_instance"][:]
        train, test = ds.splits["train"], ds.splits["test"]
    for ids in (subjects, instances):
        seen_train = set(ids[train][ids[train] >= 0].tolist())
        seen_test = set(ids[test][ids[test] >= 0].tolist())
        assert not seen_train & seen_test


def test_same_seed_same_bytes_for_any_worker_count(mixed: Path, tmp_path: Path) -> None:
    generate(config(), tmp_path / "two", workers=2, progress=False)
    assert sha256(tmp_path / "two" / "dataset.h5") == sha256(mixed / "dataset.h5")


def test_without_mixing_the_record_and_the_samples_are_the_single_contact_ones(
    tmp_path: Path,
) -> None:
    """A configuration that does not mix records no [mix] table, and writes the same bytes as a
    configuration that never had one (its samples are the single-contact generator's)."""
    plain = override(GenerateConfig(), {k: v for k, v in MIX.items() if "mix" not in k})
    off = override(plain, {"mix.fraction": 0.0})
    generate(plain, tmp_path / "plain", workers=1, progress=False)
    generate(off, tmp_path / "off", workers=1, progress=False)
    assert sha256(tmp_path / "plain" / "dataset.h5") == sha256(tmp_path / "off" / "dataset.h5")
    with open_dataset(tmp_path / "off") as ds:
        assert "mix" not in ds.attrs["config"] and "n_contacts" not in ds.fields


def test_mixing_needs_the_keyed_split() -> None:
    with pytest.raises(ConfigError, match=r"mix.fraction.*split = \"keyed\""):
        config(**{"split": "greedy"})


def test_a_sample_without_room_for_its_second_contact_is_redrawn(tmp_path: Path) -> None:
    """A gap wider than the plate leaves no room: every attempt of a two-contact sample fails
    as "no_room", and the refusal names it."""
    wide = config(**{"n": 4, "mix.fraction": 1.0, "mix.min_gap_mm": 900.0})
    with pytest.raises(ConfigError, match="no_room"):
        generate(wide, tmp_path / "x", workers=1, progress=False)
