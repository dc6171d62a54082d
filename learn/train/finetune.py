"""Fine-tuning a segmenter trained on simulation on a few real box-labelled prints: the recipe
chosen on held-out real prints (docs/findings.md), shared by `handskin finetune` and the
`real-finetune` experiment.

    recipe = FinetuneRecipe()  # 300 steps, 300 simulated replayed, moved 18 mm, turned 15 deg
    result, run, copies = finetune(base, real, replay, shift, recipe, init=ckpt, out="runs/ft")

The network trains with the preset SegNet's optimiser, loss (median-frequency weighted
cross-entropy over the box-derived labels, unlabelled pixels ignored), batch and learning-rate
drop, for a fixed number of steps (``steps``) whatever the number of real prints. Beside the real
prints it replays simulated ones (``replay``, seeded, from a train split): what keeps a handful
of prints from pulling the network off everything it learnt (10 held-out-fold prints: 69.6 %
part localisation without replay, 73.9 % with 300; zero-shot 69.7). Each real print is repeated
to about as many as the replayed ones, every copy but the first moved and turned (``shift_mm``,
``turn_deg``; `learn.data.augment`): the same hand pressing elsewhere on the link, at another
angle (10 prints, five draws: 72.6 % unmoved, 74.2 % moved up to 18 mm, 75.8 % also turned up to
15 deg).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from learn.config import SEGNET, RunConfig
from tactile.errors import ConfigError, DataError
from tactile.images.labels import CLASS_NAMES

KEY_REPLAY = 1  # the replay pick's stream: SeedSequence(seed, spawn_key=(KEY_REPLAY, replay))
KEY_MOVES = 2  # the moved copies' stream: SeedSequence(seed, spawn_key=(KEY_MOVES, k, draw))


@dataclass(frozen=True)
class FinetuneRecipe:
    """Optimisation ``steps`` (count), simulated prints replayed beside the real ones
    (``replay``, count; 0: none), how far copies of the real prints are moved on the map
    (``shift_mm``, mm, up to) and turned (``turn_deg``, deg, up to; both 0: plain repeats), the
    ``seed`` of the replay pick, the copies and training, CPU ``threads``."""

    steps: int = 300
    replay: int = 300
    shift_mm: float = 18.0
    turn_deg: float = 15.0
    seed: int = 0
    threads: int = 2

    def __post_init__(self) -> None:
        if self.steps < 1:
            raise ConfigError(f"--steps {self.steps}: a count >= 1 of optimisation steps")
        if self.replay < 0:
            raise ConfigError(f"--replay {self.replay}: a count >= 0 of simulated prints")
        if not self.shift_mm >= 0:
            raise ConfigError(f"--shift-mm {self.shift_mm}: a distance >= 0 mm (0: not moved)")
        if not 0 <= self.turn_deg <= 180:
            raise ConfigError(
                f"--turn-deg {self.turn_deg}: an angle in [0, 180] deg (0: not turned)"
            )

    @property
    def moves(self) -> bool:
        """Whether copies of the real prints are moved or turned."""
        return self.shift_mm > 0 or self.turn_deg > 0


def run_config(base: RunConfig, n: int, recipe: FinetuneRecipe, draw: int = 0) -> RunConfig:
    """The preset SegNet recipe on ``base``'s network, for ``recipe.steps`` steps on n prints
    (real and replayed) in the paper's three views (the lr drops after two thirds of the
    epochs), no validation; training seeded by ``recipe.seed + draw``."""
    per_epoch = math.ceil(3 * n / SEGNET.train.batch_size)
    epochs = max(1, math.ceil(recipe.steps / per_epoch))
    train = dataclasses.replace(
        SEGNET.train,
        epochs=epochs,
        lr_drop_period_epochs=max(1, round(2 * epochs / 3)),
        seed=recipe.seed + draw,
    )
    return dataclasses.replace(base, train=train, val_fraction=0.0, threads=recipe.threads)


def replay_source(
    sim: Path | None, base: RunConfig, recipe: FinetuneRecipe, ckpt: dict, pretrained: str
):
    """(dataset path, its fingerprint, its train split's hand prints as a torch dataset) to
    replay: ``sim`` (``--replay-from``), else the dataset the network trained on (its
    checkpoint's data path); (None, None, None) when ``recipe.replay`` is 0. Checked before any
    work: a dataset, holding ``recipe.replay`` training prints, and, with both fingerprints
    known, the one the network trained on (``pretrained``: the checkpoint's path, for errors)."""
    from learn.data.load import fingerprint, is_dataset, open_split

    if recipe.replay == 0:
        if sim is not None:
            raise ConfigError(f"--replay-from {sim} with --replay 0: leave one of them out")
        return None, None, None
    stored = ckpt.get("data") or {}
    if sim is None:
        if stored.get("path") is None or not is_dataset(stored["path"]):
            where = stored.get("path", "data it does not name")
            raise DataError(
                f"{pretrained}: trained on {where}, not a dataset found here, so there is "
                "nothing to replay. Fix: --replay-from the simulated dataset, or --replay 0"
            )
        sim, flag = Path(stored["path"]), f"{stored['path']} (where {pretrained} trained)"
    elif not is_dataset(sim):
        raise DataError(f"--replay-from {sim}: not a handskin dataset. Fix: handskin generate")
    else:
        flag = f"--replay-from {sim}"
    now, theirs = fingerprint(sim), stored.get("fingerprint")
    if (
        now is not None
        and theirs is not None
        and Path(sim).resolve() == Path(stored.get("path", "")).resolve()
        and now != theirs
    ):
        raise DataError(
            f"{flag}: generated again since {pretrained} trained on it (fingerprint "
            f"{theirs[:12]}, now {now[:12]}). Fix: --replay-from the dataset it trained on"
        )
    size, canvas = base.model.input_size, base.model.canvas_mm
    ds = open_split(sim, "train", "segment", size, None, recipe.seed, canvas)
    if recipe.replay > len(ds):
        raise ConfigError(
            f"--replay {recipe.replay}: {sim} holds {len(ds)} hand prints in its train split. "
            f"Fix: --replay {len(ds)} or less"
        )
    return Path(sim), now, ds


def replay_prints(ds, recipe: FinetuneRecipe):
    """``recipe.replay`` prints of ``ds`` (TensorData), a seeded pick; None without a source."""
    from learn.data.load import materialize
    from learn.data.load import subset as positions_of

    if ds is None:
        return None
    seq = np.random.SeedSequence(recipe.seed, spawn_key=(KEY_REPLAY, recipe.replay))
    pick = np.sort(np.random.default_rng(seq).choice(len(ds), recipe.replay, replace=False))
    return materialize(positions_of(ds, pick), "replay", False)


def copies_of(k: int, recipe: FinetuneRecipe, start: str = "simulation") -> int:
    """Copies of each of ``k`` real prints a run from ``start`` ("simulation": pretrained;
    "random") trains on: about as many in all as the replayed simulated prints, at least one.
    With moved copies both starts take the same copies, at least two; without, a random start
    takes the prints once."""
    if start == "random" and not recipe.moves:
        return 1
    return max(2 if recipe.moves else 1, recipe.replay // k)


def shift_px(recipe: FinetuneRecipe, frame_mm: tuple[int, int], size: tuple[int, int]) -> int:
    """``recipe.shift_mm`` in network input pixels: a ``frame_mm`` (rows, columns; the paper's
    1 mm grid) image resized to ``size`` (h, w) px."""
    return round(recipe.shift_mm * min(size[0] / frame_mm[0], size[1] / frame_mm[1]))


def training_set(real, sim, copies: int, shift: int, recipe: FinetuneRecipe, draw: int = 0):
    """Images and targets of a run: the replayed simulated prints (``sim``; None: none), then
    ``copies`` of the real ones (``real``: TensorData), all but the first moved by up to
    ``shift`` px and turned by up to ``recipe.turn_deg`` (`learn.data.augment.moved_copies`;
    seeded by the count of real prints and ``draw``, so two starts see the same copies)."""
    import torch  # optional: the learn extra (this module's recipe is read without it)

    from learn.data.augment import moved_copies

    seq = np.random.SeedSequence(recipe.seed, spawn_key=(KEY_MOVES, len(real.y), draw))
    rng = np.random.default_rng(seq)
    x, y = moved_copies(real.x, real.y, copies, shift, recipe.turn_deg, rng)
    if sim is None:
        return x, y
    return torch.cat([sim.x, x]), torch.cat([sim.y, y])


def finetune(base: RunConfig, real, replay, shift: int, recipe: FinetuneRecipe, **kw):
    """Train ``base``'s network by the recipe on copies of the ``real`` prints (TensorData,
    with its mirror pairs) beside the ``replay`` ones (None: none); returns (FitResult, the
    RunConfig, copies of each real print). Keywords: ``init`` (checkpoint dict; None: a random
    start), ``start`` ("simulation" or "random", for `copies_of`), ``draw``, ``out`` (run
    folder; None writes nothing), ``description`` (the checkpoint's data), ``progress``."""
    from learn.data.load import Data, TensorData
    from learn.train.loop import fit

    draw = kw.get("draw", 0)
    copies = copies_of(len(real.y), recipe, kw.get("start", "simulation"))
    x, y = training_set(real, replay, copies, shift, recipe, draw)
    run = run_config(base, len(y), recipe, draw)
    data = Data(TensorData(x, y, real.mirror), None, None, CLASS_NAMES, kw.get("description", {}))
    result = fit(run, data, kw.get("out"), init=kw.get("init"), progress=kw.get("progress", False))
    return result, run, copies
