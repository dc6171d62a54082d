"""Building blocks of primitive contactors: named primitives, rigid transforms, support
points, volumes, compliance by material, and assembly into a `ContactorSpec` (objects and body
parts share them; see `sim.contactors.objects` for the stiffness argument).
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from sim.contactors.spec import ROOT, ContactorSpec
from tactile.errors import ConfigError

SHAPES = {
    "sphere": mujoco.mjtGeom.mjGEOM_SPHERE,
    "capsule": mujoco.mjtGeom.mjGEOM_CAPSULE,
    "cylinder": mujoco.mjtGeom.mjGEOM_CYLINDER,
    "box": mujoco.mjtGeom.mjGEOM_BOX,
    "ellipsoid": mujoco.mjtGeom.mjGEOM_ELLIPSOID,
}
# material: (density kg/m^3, compliance depth range m (solimp width), sliding friction)
MATERIALS: dict[str, tuple[float, tuple[float, float], float]] = {
    "steel": (7850.0, (0.0010, 0.0015), 0.5),
    "aluminium": (2700.0, (0.0010, 0.0015), 0.5),
    "ceramic": (2300.0, (0.0010, 0.0015), 0.6),
    "wood": (600.0, (0.0015, 0.0030), 0.6),
    "hard_plastic": (1100.0, (0.0015, 0.0030), 0.4),
    "rubber": (1100.0, (0.0030, 0.0060), 1.0),
    "foam": (50.0, (0.0060, 0.0120), 1.0),
    "padding": (40.0, (0.0150, 0.0300), 0.9),  # cushions, stuffed bags, clothes: see below
    "inflatable": (30.0, (0.0150, 0.0300), 0.8),  # soft inflated balls: see below
    "soft_tissue": (1050.0, (0.0120, 0.0250), 0.8),  # fat and muscle over bone: see below
    "thin_tissue": (1050.0, (0.0060, 0.0120), 0.8),  # skin and pads over bone: see below
}
# Thick compliant contactors get the hands' rule (`sim.contactors.hand`: allowance ~ 1-2.5 x the
# tissue's thickness, palm 10.5 mm over 8-15 mm of tissue, fingertip 8.75 mm over 3-5 mm of pulp):
# - soft_tissue 12-25 mm: fat plus relaxed muscle over the ulna/humerus, ribs or scapula is
#   2-5 cm thick (ultrasound: subcutaneous fat 3-10 mm on the forearm, 5-20 mm over triceps,
#   chest and back; muscle 10-40 mm); at 10-100 N it indents 30-50 % of that (soft-tissue
#   indentation of the limbs, e.g. Zheng & Mak 1999: moduli 10-100 kPa, tissue 1-5 cm);
# - thin_tissue 6-12 mm: skin, fat and bursa over the olecranon and patella, scalp (5-10 mm
#   thick), at the fingertip's 2-2.5 x;
# - padding 15-30 mm: cushions, stuffed bags, folded clothes (upholstery foam E ~ 5-20 kPa,
#   5-15 cm thick, 10-30 % strain at tens of N on a hand-sized area);
# - inflatable 15-30 mm: gym, beach and toy balls at 1-20 kPa gauge spread 30 N over
#   15-300 cm^2, a flattening of centimetres.
SOLREF = (0.01, 1.0)  # s, damping ratio: the hand's; >= 2 time steps up to dt = 5 ms
# max_penetration_m / largest compliance depth: readings reach 0.5-1.3 x the depth under 40 N;
# MuJoCo's box distance reads up to sqrt(3) x deeper near edges (sim.skin.readout), so thin boxes
# (rulers, plates) reach 2.3 x (measured): allow 3 x when there is a box.
PENETRATION_FACTOR, BOX_PENETRATION_FACTOR = 2.0, 3.0
FINGER_RADIUS_M = (0.006, 0.011)  # hand phalanx radii, sim.contactors.hand_kinematics
# finger centre spacing (MCP pitch), sim.contactors.hand_kinematics
FINGER_SPACING_M = (0.015, 0.025)
PREFIX = "obj_"


@dataclass(frozen=True)
class Prim:
    """One primitive in the contactor frame: ``size`` MuJoCo's, ``pos`` (3,) m, ``mat`` (3, 3)."""

    name: str
    shape: str
    size: tuple[float, ...]
    pos: np.ndarray
    mat: np.ndarray
    material: str


def instance_rng(kind: str, instance_id: int) -> np.random.Generator:
    """The generator of one instance: depends only on (kind, instance_id)."""
    if instance_id < 0:
        raise ConfigError(f"instance_id={instance_id} must be >= 0")
    return np.random.default_rng(np.random.SeedSequence((zlib.crc32(kind.encode()), instance_id)))


def prim(name: str, shape: str, size, pos=(0.0, 0.0, 0.0), mat=None, material="wood") -> Prim:
    """A primitive at ``pos`` (m) with orientation ``mat`` (3, 3; identity if None)."""
    m = np.eye(3) if mat is None else np.asarray(mat, dtype=float)
    sizes = tuple(float(s) for s in size)
    return Prim(name, shape, sizes, np.asarray(pos, dtype=float), m, material)


def segment(name: str, shape: str, a, b, radius_m: float, material: str) -> Prim:
    """Capsule or cylinder from point ``a`` to ``b`` (3,) m with radius ``radius_m``."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    axis = b - a
    quat = np.zeros(4)
    mujoco.mju_quatZ2Vec(quat, axis / np.linalg.norm(axis))
    mat = Rotation.from_quat(quat, scalar_first=True).as_matrix()
    return prim(name, shape, (radius_m, np.linalg.norm(axis) / 2), (a + b) / 2, mat, material)


def rot(axis: str, angle_rad: float) -> np.ndarray:
    """(3, 3) rotation about a frame axis "x", "y" or "z"."""
    return Rotation.from_euler(axis, angle_rad).as_matrix()


def rotate(prims: list[Prim], mat: np.ndarray) -> list[Prim]:
    """The primitives turned by ``mat`` (3, 3) about the frame origin."""
    return [Prim(p.name, p.shape, p.size, mat @ p.pos, mat @ p.mat, p.material) for p in prims]


def _sign(x: np.ndarray) -> np.ndarray:
    return np.where(np.abs(x) < 1e-9, 0.0, np.sign(x))


def support_point(p: Prim) -> np.ndarray:
    """Lowest point (3,) m of ``p`` along -z (the centre of a lowest face or line when flat)."""
    u, s = p.mat.T @ np.array([0.0, 0.0, -1.0]), np.asarray(p.size)
    if p.shape == "sphere":
        local = s[0] * u
    elif p.shape == "capsule":
        local = s[0] * u + [0.0, 0.0, s[1] * _sign(u[2])]
    elif p.shape == "cylinder":
        nr = np.linalg.norm(u[:2])
        radial = s[0] * u[:2] / nr if nr > 1e-9 else np.zeros(2)
        local = np.array([*radial, s[1] * _sign(u[2])])
    elif p.shape == "box":
        local = s[:3] * _sign(u)
    else:
        local = s[:3] ** 2 * u / np.linalg.norm(s[:3] * u)
    return p.pos + p.mat @ local


def anchor_m(prims: list[Prim], band_m: float = 0.001) -> np.ndarray:
    """(3,) m: xy = mean lowest point of the primitives within ``band_m`` of the lowest height,
    z = that height. Moving it to the origin puts the first contact over the skin point."""
    points = np.array([support_point(p) for p in prims])
    low = points[:, 2] <= points[:, 2].min() + band_m
    return np.array([*points[low, :2].mean(axis=0), points[:, 2].min()])


def volume_m3(p: Prim) -> float:
    """Volume of one primitive, m^3."""
    s = p.size
    return {
        "sphere": lambda: 4 / 3 * np.pi * s[0] ** 3,
        "capsule": lambda: np.pi * s[0] ** 2 * 2 * s[1] + 4 / 3 * np.pi * s[0] ** 3,
        "cylinder": lambda: np.pi * s[0] ** 2 * 2 * s[1],
        "box": lambda: 8 * s[0] * s[1] * s[2],
        "ellipsoid": lambda: 4 / 3 * np.pi * s[0] * s[1] * s[2],
    }[p.shape]()


def draw_compliance(rng: np.random.Generator, prims: list[Prim]) -> dict[str, float]:
    """Compliance depth (m) per material of ``prims``, uniform in the material's range."""
    return {m: float(rng.uniform(*MATERIALS[m][1])) for m in sorted({p.material for p in prims})}


def assemble(
    prims: list[Prim],
    kind: str,
    name: str,
    instance_id: int,
    *,
    dims: dict,
    compliance: dict[str, float],
    fill: float = 1.0,
    prefix: str = PREFIX,
) -> ContactorSpec:
    """A `ContactorSpec` of ``prims`` moved so that `anchor_m` is the root origin.

    The geoms live in one body ``<prefix>body`` under ``root``, named ``<prefix><name>_<part>``;
    density = material density x ``fill`` (hollow objects). ``dims`` (m) go into the description.
    """
    lift = -anchor_m(prims)
    spec = mujoco.MjSpec()
    spec.modelname = f"{prefix}{name}"
    body = spec.worldbody.add_body(name=ROOT).add_body(name=f"{prefix}body")
    labels = {}
    for p in prims:
        gname = f"{prefix}{name}_{p.name}"
        _add_geom(body, gname, p, lift, compliance[p.material], fill)
        labels[gname] = 0
    mass = sum(volume_m3(p) * MATERIALS[p.material][0] * fill for p in prims)
    desc = {
        "type": name,
        "kind": kind,
        "instance_id": int(instance_id),
        "dimensions_m": dims,
        "materials": {p.name: p.material for p in prims},
        "mass_kg": round(float(mass), 4),
        "stiffness": {"compliance_depth_m": compliance, "solref": list(SOLREF)},
    }
    return ContactorSpec(
        spec,
        labels,
        kind,
        name,
        instance_id=int(instance_id),
        description=desc,
        max_penetration_m=_factor(prims) * max(compliance.values()),
    )


def _factor(prims: list[Prim]) -> float:
    boxes = any(p.shape == "box" for p in prims)
    return BOX_PENETRATION_FACTOR if boxes else PENETRATION_FACTOR


def _add_geom(body, name: str, p: Prim, lift: np.ndarray, width_m: float, fill: float) -> None:
    density, _, friction = MATERIALS[p.material]
    quat = Rotation.from_matrix(p.mat).as_quat(scalar_first=True)
    body.add_geom(
        name=name,
        type=SHAPES[p.shape],
        size=list(p.size) + [0.0] * (3 - len(p.size)),
        pos=(p.pos + lift).tolist(),
        quat=quat.tolist(),
        density=density * fill,
        contype=2,
        conaffinity=1,
        group=3,
        priority=1,
        condim=3,
        friction=[friction, 0.005, 0.0001],
        solref=list(SOLREF),
        solimp=[0.0, 0.99, width_m, 0.5, 2.0],
        rgba=[0.85, 0.55, 0.25, 1.0],
    )


def _dims(**kw: float) -> dict[str, float]:
    return {k: round(float(v), 5) for k, v in kw.items()}


def unif(rng: np.random.Generator, lo: float, hi: float, log: bool = False) -> float:
    """Uniform (or log-uniform) draw in [lo, hi]."""
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))) if log else rng.uniform(lo, hi))


def pick(rng: np.random.Generator, options) -> str:
    return str(options[int(rng.integers(len(options)))])
