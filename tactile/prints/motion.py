"""How a print moves on the map between two frames, in the hand's own axes: what can tell a
mirror pair apart (a push to one side of the hand from a push to the other, a clockwise twist
from a counter-clockwise one) on a skin that reads pressure, not shear.

    axis = hand_axis(tmap, label_image)            # (2,) unit (u, v): palm -> fingers, or None
    across_mm, turn_deg = print_motion(p0, p1, tmap.uv, axis)

``across_mm``: the centre of pressure's shift from frame ``p0`` to ``p1`` across the hand, along
the axis turned a quarter turn counter-clockwise in (u, v), mm. ``turn_deg``: the turn of the
pressure's principal axis, counter-clockwise in (u, v), degrees in [-90, 90).
"""

from __future__ import annotations

import numpy as np

from tactile.images.labels import CLASS_NAMES
from tactile.images.tactile_map import TactileMap

PALM = CLASS_NAMES.index("palm")
FINGERS = tuple(CLASS_NAMES.index(n) for n in ("index", "middle", "ring", "pinkie"))
MIN_PIXELS = 5  # fewer palm or finger pixels than this: no axis


def hand_axis(tmap: TactileMap, label_image: np.ndarray) -> np.ndarray | None:
    """(2,) unit vector in (u, v) from the palm's pixels' centroid to the four fingers' (the
    hand's distal direction), from a label image (H, W) of class ids; None when either has
    fewer than `MIN_PIXELS` pixels."""
    centres = tmap.pixel_centers()
    palm, fingers = label_image == PALM, np.isin(label_image, FINGERS)
    if palm.sum() < MIN_PIXELS or fingers.sum() < MIN_PIXELS:
        return None
    axis = centres[fingers].mean(0) - centres[palm].mean(0)
    norm = np.linalg.norm(axis)
    return axis / norm if norm > 0 else None


def centre_of_pressure(p: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """(2,) mm: the pressure-weighted mean of the placed taxels' uv (N, 2) mm."""
    placed = np.isfinite(uv).all(1)
    w = p[placed]
    return w @ uv[placed] / w.sum()


def principal_angle(p: np.ndarray, uv: np.ndarray) -> float:
    """Radians in (u, v): the direction of the largest spread of pressure around its centre."""
    placed = np.isfinite(uv).all(1)
    w, xy = p[placed] / p[placed].sum(), uv[placed]
    d = xy - w @ xy
    major = np.linalg.eigh((d * w[:, None]).T @ d)[1][:, -1]
    return float(np.arctan2(major[1], major[0]))


def print_motion(
    p0: np.ndarray, p1: np.ndarray, uv: np.ndarray, axis: np.ndarray
) -> tuple[float, float]:
    """(across_mm, turn_deg) from frame ``p0`` (N,) Pa to ``p1`` (N,) Pa (module docstring)."""
    across = np.array([-axis[1], axis[0]])
    shift = float((centre_of_pressure(p1, uv) - centre_of_pressure(p0, uv)) @ across)
    turn = principal_angle(p1, uv) - principal_angle(p0, uv)
    return shift, float(np.degrees((turn + np.pi / 2) % np.pi - np.pi / 2))
