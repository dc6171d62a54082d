"""Speed of the forearm scene and of readout + skin model (printed, never asserted).

    PYTHONPATH=. python benchmarks/bench_skin.py

Scene: the forearm (768 taxels, tactile sensor) with three force-driven contactors (two spheres and
a box) pressing it. Reports simulation steps per second with and without sensor evaluation, and the
cost per frame of the readout (depth, world positions of touched taxels, attribution) plus the
skin model (foundation law, spread, gain, baseline/drift, noise, quantization). Target: readout +
skin model <= 1 ms per 768-taxel frame on one core.
"""

from __future__ import annotations

import platform
import time

import mujoco
import numpy as np

from sim.episode.scene import Contactor, SkinScene
from sim.skin.model import SkinConfig, SkinInstance
from sim.skin.parts import get_part

N_STEPS = 2000
N_FRAMES = 2000


def pressing_scene() -> SkinScene:
    part = get_part("forearm")
    pos, nrm = part.layout.positions_m, part.layout.normals
    picks = [100, 400, 650]
    shapes = [("sphere", (0.015,)), ("sphere", (0.02,)), ("box", (0.012, 0.012, 0.01))]
    contactors = [
        Contactor(
            f"c{i}",
            shape,
            size,
            tuple(pos[t] + nrm[t] * (size[-1] + 1e-3)),
            tuple(-nrm[t]),
            label=i + 1,
        )
        for i, (t, (shape, size)) in enumerate(zip(picks, shapes, strict=True))
    ]
    scene = SkinScene(part, contactors)
    for c in contactors:
        scene.set_force(c.name, 5.0)
    scene.step(300)  # settle into contact
    return scene


def steps_per_second(scene: SkinScene, sensors: bool) -> float:
    flag = int(mujoco.mjtDisableBit.mjDSBL_SENSOR)
    scene.model.opt.disableflags = 0 if sensors else flag
    start = time.perf_counter()
    scene.step(N_STEPS)
    elapsed = time.perf_counter() - start
    scene.model.opt.disableflags = 0
    return N_STEPS / elapsed


def frame_cost_us(scene: SkinScene) -> tuple[float, float, int]:
    skin = SkinInstance.create(
        scene.part.layout.positions_m, SkinConfig(), np.random.default_rng(0)
    )
    rng = np.random.default_rng(1)
    scene.forward()
    t0 = time.perf_counter()
    for _ in range(N_FRAMES):
        frame = scene.read()
    t1 = time.perf_counter()
    for _ in range(N_FRAMES):
        skin.frame(frame.depth_m, rng, time_s=1.0)
    t2 = time.perf_counter()
    return (t1 - t0) / N_FRAMES * 1e6, (t2 - t1) / N_FRAMES * 1e6, int((frame.contactor >= 0).sum())


def main() -> None:
    scene = pressing_scene()
    with_sensor = steps_per_second(scene, True)
    without = steps_per_second(scene, False)
    readout_us, skin_us, active = frame_cost_us(scene)
    print(
        f"mujoco {mujoco.__version__}, numpy {np.__version__}, python {platform.python_version()}"
    )
    print(
        f"forearm scene: {scene.part.n_taxels} taxels, {scene.data.ncon} contacts, "
        f"{active} taxels pressed, timestep {scene.model.opt.timestep * 1e3:g} ms"
    )
    real_time = with_sensor * scene.model.opt.timestep
    print(f"steps/s with tactile sensor    {with_sensor:10.0f}  (x{real_time:.1f} real time)")
    print(f"steps/s without sensors        {without:10.0f}")
    print(f"readout per frame              {readout_us:10.1f} us")
    print(f"skin model per frame           {skin_us:10.1f} us")
    total = readout_us + skin_us
    print(
        f"readout + skin model           {total:10.1f} us  (target <= 1000 us: "
        f"{'met' if total <= 1000 else 'NOT met'})"
    )


if __name__ == "__main__":
    main()
