"""Shared fixtures: the real public data in ../shared/data (never copied into the project), the
keyed split's rule written out slowly."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Path of ../shared/data; the test is skipped with the reason when the folder is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real public data not found at {SHARED_DATA} (see the brief: ../shared/data)")
    return SHARED_DATA


@pytest.fixture(scope="session")
def icub_positions(shared_data: Path) -> Path:
    """Folder of the real iCub calibration files (positions/*.txt)."""
    path = shared_data / "icub_skin" / "positions"
    if not path.is_dir():
        pytest.skip(f"iCub skin layouts not found at {path}")
    return path


def keyed_reference_sides(keys, seed: int, fraction: float = 0.7, stream: int = 0) -> dict:
    """The keyed split's documented rule, written out slowly (tactile.dataset.splits):
    {(kind, id): in train} for unit keys (0, subject) — hands — and (1, instance) — the rest.
    Train when the uniform draw of SeedSequence([seed, stream, kind, id]) is below ``fraction``;
    a class all on one side gives up the unit whose draw lies nearest the threshold."""
    draws = {}
    for key in keys:
        bits = np.random.PCG64(np.random.SeedSequence([seed, stream, *key]))
        draws[key] = np.random.Generator(bits).random()
    sides = {k: d < fraction for k, d in draws.items()}
    for kind in (0, 1):
        mine = [k for k in keys if k[0] == kind]
        if len(mine) >= 2 and len({sides[k] for k in mine}) == 1:
            moved = (max if sides[mine[0]] else min)(mine, key=draws.__getitem__)
            sides[moved] = not sides[moved]
    return sides


def group_sides(subject_id, instance_id, train_index) -> dict:
    """{(0, subject) or (1, instance): in train} of samples with one id each, from the train
    indices; asserts that no subject or instance lies on both sides."""
    train = np.zeros(len(subject_id), bool)
    train[np.asarray(train_index, dtype=np.int64)] = True
    sides: dict = {}
    for s, i, t in zip(
        np.asarray(subject_id).tolist(),
        np.asarray(instance_id).tolist(),
        train.tolist(),
        strict=True,
    ):
        sides.setdefault((0, s) if s >= 0 else (1, i), set()).add(t)
    assert all(len(v) == 1 for v in sides.values()), "a subject or instance on both sides"
    return {k: v.pop() for k, v in sides.items()}


@pytest.fixture(scope="session")
def keyed_reference():
    """(keyed_reference_sides, group_sides): the keyed split's rule and a dataset's sides."""
    return keyed_reference_sides, group_sides


#: Score margin within which two runs of one network may decide differently. A batch of another
#: size or layout, or another CPU, runs other kernels (oneDNN and BLAS choose by instruction set
#: and shape), whose float32 sums come in another order: the tests' small networks then give
#: logits and probabilities about 1e-6 apart, so only decisions whose two best scores lie closer
#: than this can differ. Exactly equal inputs are the job of `tactile.images.resize.resize_grey`.
NEAR_TIE = 1e-4


class NearTies:
    """Comparisons of decisions made by one network run two ways, exact but at near ties."""

    margin = NEAR_TIE

    @staticmethod
    def count(scores) -> int:
        """Decisions along axis 1 of ``scores`` (B, C, ...) (logits or probabilities) whose two
        best scores lie within `NEAR_TIE`."""
        import torch

        top = torch.as_tensor(np.asarray(scores, np.float64)).topk(2, dim=1).values
        return int(((top[:, 0] - top[:, 1]) < NEAR_TIE).sum())

    @classmethod
    def assert_cm(cls, got, want, scores) -> None:
        """Confusion matrices equal but for the near ties of the reference's ``scores``: each
        decision made the other way moves one count from one cell to another."""
        diff = np.abs(np.asarray(got) - np.asarray(want)).sum()
        assert np.asarray(got).sum() == np.asarray(want).sum()
        assert diff <= 2 * cls.count(scores), (diff, cls.count(scores), got, want)

    @classmethod
    def assert_rate(cls, got: float, want: float, scores) -> None:
        """A share of right decisions (accuracy) equal but for the near ties of ``scores``."""
        n = len(scores)
        assert abs(got - want) <= cls.count(scores) / n + 1e-12, (got, want, cls.count(scores))


@pytest.fixture(scope="session")
def near_ties() -> type[NearTies]:
    """`NearTies`: decisions compared exactly but at near ties (`NEAR_TIE`)."""
    return NearTies
