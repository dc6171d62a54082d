"""Speed of the tactile map on the forearm-like layout (~860 taxels, 1 mm grid), single core.

Run: ``PYTHONPATH=. python benchmarks/bench_tactile.py``. Prints each figure, its target and the
ratio figure / target (>= 1 meets the target). Figures are never asserted in tests.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ[_var] = "1"  # before numpy is imported

import time  # noqa: E402
from collections.abc import Callable  # noqa: E402

import matplotlib.tri as mtri  # noqa: E402
import numpy as np  # noqa: E402
from scipy.spatial import Delaunay  # noqa: E402
from skimage.morphology import dilation, disk, erosion  # noqa: E402

from tactile.geometry.synthetic import cylinder_sector_layout  # noqa: E402
from tactile.images import morphology  # noqa: E402
from tactile.images.tactile_map import TactileMap  # noqa: E402

BATCH = 64  # frames per batched call


def best_seconds(fn: Callable[[], object], repeat: int = 5, number: int = 3) -> float:
    """Best mean wall time of ``number`` calls over ``repeat`` rounds (after one warm-up call)."""
    fn()
    best = np.inf
    for _ in range(repeat):
        start = time.perf_counter()
        for _ in range(number):
            fn()
        best = min(best, (time.perf_counter() - start) / number)
    return best


def report(name: str, value: float, target: float | None, unit: str, lower: bool = False) -> None:
    """Print a figure, its target and value/target (target/value when lower is better)."""
    line = f"{name:<44s} {value:>10.3f} {unit:<9s}"
    if target is not None:
        ratio = target / value if lower else value / target
        line += f" target {'<=' if lower else '>='} {target:<8g} ratio {ratio:6.2f}"
    print(line)


def matplotlib_frames(tmap: TactileMap, frames: np.ndarray) -> Callable[[], object]:
    """LinearTriInterpolator per frame on the same mesh and pixel centres (trifinder reused)."""
    tri = mtri.Triangulation(*tmap.vertex_uv_mm.T, tmap.faces)
    finder = tri.get_trifinder()
    centres = tmap.pixel_centers()

    def run() -> None:
        for p in frames:
            interp = mtri.LinearTriInterpolator(tri, p[tmap.vertex_taxel], trifinder=finder)
            interp(centres[..., 0], centres[..., 1])

    return run


def main() -> None:
    layout, flat_mm = cylinder_sector_layout()
    uv = np.column_stack([flat_mm[:, 1], -flat_mm[:, 0]])
    faces = Delaunay(uv).simplices
    ids = np.arange(len(uv))
    tmap = TactileMap.from_flat(layout.positions_m, uv, ids, faces)
    print(f"layout: {layout.n_taxels} taxels, {len(faces)} triangles; grid {tmap.shape} px at 1 mm")
    frames = np.random.default_rng(0).random((BATCH, tmap.n_taxels)) * 1e4

    t = best_seconds(lambda: TactileMap.build(layout), repeat=2, number=1)
    report("map build (triangulate+flatten+table)", t, 2.0, "s", lower=True)
    t = best_seconds(lambda: TactileMap.from_flat(layout.positions_m, uv, ids, faces), repeat=3)
    report("  of which look-up table (from_flat)", t, 2.0, "s", lower=True)

    t = best_seconds(lambda: tmap.image(frames[0]), number=20)
    report("image, one frame", 1 / t, 500, "frames/s")
    t = best_seconds(lambda: tmap.image(frames), number=1)
    report(f"image, batch of {BATCH}", BATCH / t, 500, "frames/s")
    t_one = best_seconds(lambda: tmap.interpolate(frames[0]), number=20)
    report("interpolate, one frame (float64)", 1 / t_one, 5000, "frames/s")
    t_b64 = best_seconds(lambda: tmap.interpolate(frames), number=2)
    report(f"interpolate, batch of {BATCH} (float64)", BATCH / t_b64, 5000, "frames/s")
    t_b32 = best_seconds(lambda: tmap.interpolate(frames, dtype=np.float32), number=2)
    report(f"interpolate, batch of {BATCH} (float32)", BATCH / t_b32, 5000, "frames/s")

    few = frames[:8]
    t_mpl = best_seconds(matplotlib_frames(tmap, few), repeat=2, number=1) / len(few)
    report("matplotlib LinearTriInterpolator (reference)", 1 / t_mpl, None, "frames/s")
    report("  speed-up, batched float64 vs matplotlib", t_mpl / (t_b64 / BATCH), 20, "x")
    report("  speed-up, one frame vs matplotlib", t_mpl / t_one, 20, "x")

    grey = tmap.image(frames[0], erode_px=0, dilate_px=0)
    t_ours = best_seconds(lambda: morphology.erode_dilate(grey, 2, 4), number=20)
    t_sk = best_seconds(lambda: dilation(erosion(grey, disk(2)), disk(4)), number=5)
    report("morphology erode(2)+dilate(4), one image", t_ours * 1e3, None, "ms")
    report("  speed-up vs skimage erosion+dilation", t_sk / t_ours, 1, "x")


if __name__ == "__main__":
    main()
