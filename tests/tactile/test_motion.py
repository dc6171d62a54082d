"""A print's motion in the hand's axes (`tactile.prints.motion`), against fields moved by known
amounts: an elongated Gaussian print shifted and turned on a flat grid of taxels, and a label image
whose palm and fingers lie along a known direction."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import Delaunay

from tactile.images.tactile_map import TactileMap
from tactile.prints.motion import FINGERS, PALM, hand_axis, print_motion

STEP_MM = 4.0


@pytest.fixture(scope="module")
def plate() -> TactileMap:
    """Taxels every 4 mm on a flat 240 x 160 mm sheet."""
    u, v = np.meshgrid(np.arange(-120, 121, STEP_MM), np.arange(-80, 81, STEP_MM))
    uv = np.column_stack([u.ravel(), v.ravel()]).astype(float)
    pos = np.column_stack([uv / 1e3, np.zeros(len(uv))])
    return TactileMap.from_flat(pos, uv, np.arange(len(uv)), Delaunay(uv).simplices)


def print_at(uv: np.ndarray, centre, angle_rad: float) -> np.ndarray:
    """An elliptic Gaussian print (Pa), 30 by 10 mm (SD), its long axis at ``angle_rad``."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    d = uv - np.asarray(centre)
    along, across = d @ [c, s], d @ [-s, c]
    return 2e4 * np.exp(-0.5 * ((along / 30.0) ** 2 + (across / 10.0) ** 2))


@pytest.mark.parametrize("yaw_deg", [0.0, 37.0, 135.0, -100.0])
@pytest.mark.parametrize(("shift_mm", "turn_deg"), [(6.0, 0.0), (-4.0, 12.0), (0.0, -25.0)])
def test_a_known_shift_across_the_hand_and_turn_are_recovered(plate, yaw_deg, shift_mm, turn_deg):
    axis = np.array([np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))])
    across = np.array([-axis[1], axis[0]])
    start = np.array([5.0, -3.0])
    p0 = print_at(plate.uv, start, np.radians(yaw_deg))
    p1 = print_at(plate.uv, start + shift_mm * across + 2.0 * axis, np.radians(yaw_deg + turn_deg))
    got_shift, got_turn = print_motion(p0, p1, plate.uv, axis)
    assert got_shift == pytest.approx(shift_mm, abs=0.05)
    assert got_turn == pytest.approx(turn_deg, abs=0.5)


def test_the_hand_axis_points_from_the_palm_to_the_fingers(plate) -> None:
    centres = plate.pixel_centers()
    labels = np.zeros(plate.shape, np.uint8)
    direction = np.array([np.cos(0.6), np.sin(0.6)])  # in (u, v)
    along = centres @ direction
    near = np.linalg.norm(centres - (along[..., None] * direction), axis=-1) < 15.0
    labels[near & (np.abs(along) < 20.0)] = PALM
    labels[near & (along > 40.0) & (along < 70.0)] = FINGERS[1]
    assert hand_axis(plate, labels) == pytest.approx(direction, abs=1e-3)  # pixel steps
    labels[labels == PALM] = 0
    assert hand_axis(plate, labels) is None
