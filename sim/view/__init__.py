"""Pictures of simulated contacts: one sample as a 3D scene, rendered with pyvista; parts and
probe calibrations; contact sheets for the docs."""
