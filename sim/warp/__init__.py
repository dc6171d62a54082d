"""The MuJoCo Warp backend: many presses stepped as the worlds of one batched model (GPU, or
warp's CPU device). `options` is light; the rest imports mujoco-warp."""
