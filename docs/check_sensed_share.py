"""Do small hand prints come from hands pressing off the skin? The sensed share of the force.

    python docs/check_sensed_share.py DATASET [--n 300]

Re-simulates the first N samples of a dataset that `handskin generate` wrote, with the
dataset's own resolved configuration and episode draws (`sim.episode.episode_rng`), so sample
i is the same press; each is checked against the dataset's stored ``force_n``. At each
sample's selected frame (most active taxels) it compares the total normal force between
contactor and link (`Frame.force_n`, N) with its part on the sensorized region
(`Frame.sensed_force_n`, the resultant of the taxel pressures, N). A share near 1 means the
print shows the whole contact; a small share means most of it lies on bare link or in holes of
the skin. Printed by class and by active taxels at the selected frame.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from sim.episode import select_attempt
from sim.gen_config import GenerateConfig
from sim.generate import is_hand_index
from sim.sampler import build_state
from tactile.config import from_dict
from tactile.dataset import open_dataset
from tactile.errors import ConfigError

BINS = ((0, 10), (10, 20), (20, 40), (40, None))  # active taxels at the selected frame


def shares(data: str | Path, n: int) -> tuple[np.ndarray, ...]:
    """(is_hand bool, active taxels int, sensed share, total force N), each (n,), at the
    selected frame of the first ``n`` samples of the dataset ``data``, re-simulated.
    SystemExit when a re-simulated force differs from the dataset's ``force_n``."""
    ds = open_dataset(data)
    cfg = from_dict(GenerateConfig, ds.attrs["config"])
    n = min(n, cfg.n)
    state = build_state(cfg)
    hand, active, share, force = [], [], [], []
    for i in range(n):
        is_hand = is_hand_index(i, cfg.hand_fraction)
        make = state.hand if is_hand else state.nonhand
        try:  # the attempt the generator kept: same draws, same checks
            best = select_attempt(i, cfg.seed, state.ctx, make).frames.best
        except ConfigError as err:  # the generator would have refused this sample
            msg = f"{data}: sample {i} fails here ({err}): made by other code?"
            raise SystemExit(msg) from None
        hand.append(is_hand)
        active.append(best.active)
        share.append(best.sensed_force_n / max(best.force_n, 1e-12))
        force.append(best.force_n)
    stored = ds["force_n"][:n]
    if not np.array_equal(stored, np.float32(force)):
        worst = np.abs(stored - np.array(force)).max()
        raise SystemExit(
            f"{data}: the re-simulated forces differ from force_n (max {worst:.3g} "
            "N): made by other simulator code?"
        )
    return np.array(hand), np.array(active), np.array(share), np.array(force)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", help="dataset folder written by handskin generate")
    ap.add_argument("--n", type=int, default=300, help="samples to re-simulate (count)")
    args = ap.parse_args()
    hand, active, share, _ = shares(args.data, args.n)
    print(f"re-simulated {len(hand)} samples; each matches the dataset's force_n")
    for cls, name in ((True, "hands"), (False, "non-hands")):
        m = hand == cls
        q = np.percentile(share[m], [10, 50, 90])
        print(
            f"{name}: {m.sum()} samples; sensed share of the force, 10/50/90th percentile "
            f"{q[0]:.2f} / {q[1]:.2f} / {q[2]:.2f}"
        )
        for lo, hi in BINS:
            k = m & (active >= lo) & (active < (hi or np.inf))
            if k.any():
                span = f"{lo}-{hi - 1}" if hi else f"{lo}+"
                off = np.mean(share[k] < 0.5)
                print(
                    f"  {span:>6} active taxels: {k.sum():4d} samples, median share "
                    f"{np.median(share[k]):.2f}, under half on the skin {off:.0%}"
                )


if __name__ == "__main__":
    main()
