"""MuJoCo scenes composed with `mujoco.MjSpec`: one sensorized link plus its contactors.

`SkinScene` owns the MjSpec, MjModel and MjData and exposes named accessors; the maths lives in
`sim.skin.readout` and `sim.skin.model`. Element names are prefixed per sub-model (``fa_`` for the
part, ``obj_`` for contactors); the part's visual geoms are group 2 without collisions, the
collision geom group 3, the sensor mesh group 1 without collisions or mass. An actuator is named
after its joint.

MuJoCo only creates contacts when at least one of the two bodies has a degree of freedom: a
mocap contactor pressing a fixed (or mocap) link gives no contact and no tactile reading
(checked by experiment). Contactors therefore carry a slide or free joint, or the link a hinge.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np

from sim.skin.parts import Part
from sim.skin.readout import ReadoutFrame, TaxelReadout
from tactile.errors import ConfigError

TIMESTEP_S = 0.001  # s: 1 kHz keeps the stiff skin contacts (time constants ≥ 10 ms) stable
PART_PREFIX = "fa_"
CONTACTOR_PREFIX = "obj_"
SHAPES = {
    "sphere": mujoco.mjtGeom.mjGEOM_SPHERE,
    "capsule": mujoco.mjtGeom.mjGEOM_CAPSULE,
    "cylinder": mujoco.mjtGeom.mjGEOM_CYLINDER,
    "box": mujoco.mjtGeom.mjGEOM_BOX,
    "ellipsoid": mujoco.mjtGeom.mjGEOM_ELLIPSOID,
}


@dataclass(frozen=True)
class Contactor:
    """A rigid primitive that presses the skin, driven by a force along `press_dir`.

    size_m : MuJoCo geom size (sphere (r,), capsule/cylinder (r, half-length), box half-extents).
    The body's z axis is -press_dir (the geom's flat face or axis faces the skin); the slide
    joint ``obj_<name>`` moves along press_dir and its motor ``obj_<name>`` pushes with ctrl (N).
    """

    name: str
    shape: str
    size_m: tuple[float, ...]
    pos_m: tuple[float, float, float]
    press_dir: tuple[float, float, float] = (0.0, 0.0, -1.0)
    label: int = 0
    mass_kg: float = 0.05
    max_force_n: float = 20.0
    travel_m: float = 0.03  # slide range either way from the start, m (keeps a pulled probe near)
    solref: tuple[float, float] | None = None  # None: MuJoCo default contact softness
    solimp: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        if self.shape not in SHAPES:
            raise ConfigError(f"unknown contactor shape {self.shape!r}; known: {', '.join(SHAPES)}")
        if self.mass_kg <= 0 or self.max_force_n <= 0:
            raise ConfigError(f"contactor {self.name!r}: mass_kg and max_force_n must be > 0")


def _quat_z_to(direction: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) turning +z onto `direction` (3,)."""
    quat = np.zeros(4)
    mujoco.mju_quatZ2Vec(quat, np.asarray(direction, dtype=float) / np.linalg.norm(direction))
    return quat


def add_part(
    spec: mujoco.MjSpec,
    part: Part,
    prefix: str = PART_PREFIX,
    hinge: bool = False,
    link_file: str | None = None,
    skin_file: str | None = None,
):
    """Add the sensorized link body, its meshes and the tactile sensor. Returns the body.

    link_file, skin_file: reference the link / sensor mesh by file (written assets, MuJoCo's mesh
    cache) instead of inline vertices; a skin file must hold the taxels in layout order
    (`skin_mesh_file`), as the inline mesh does.
    """
    if link_file is None:
        spec.add_mesh(
            name=f"{prefix}link",
            uservert=part.link.vertices.ravel().tolist(),
            userface=part.link.faces.ravel().tolist(),
        )
    else:
        spec.add_mesh(name=f"{prefix}link", file=link_file)
    skin = (
        {"file": skin_file}
        if skin_file is not None
        else {
            "uservert": part.layout.positions_m.ravel().tolist(),
            "userface": part.sensor_faces.ravel().tolist(),
        }
    )
    spec.add_mesh(name=f"{prefix}skin", inertia=mujoco.mjtMeshInertia.mjMESH_INERTIA_SHELL, **skin)
    body = spec.worldbody.add_body(name=f"{prefix}link")
    if hinge:
        body.add_joint(
            name=f"{prefix}mount",
            type=mujoco.mjtJoint.mjJNT_HINGE,
            axis=[1, 0, 0],
            range=[-0.1, 0.1],
            armature=0.01,
            damping=1.0,
        )
    mesh = mujoco.mjtGeom.mjGEOM_MESH
    body.add_geom(
        name=f"{prefix}link_visual",
        type=mesh,
        meshname=f"{prefix}link",
        group=2,
        contype=0,
        conaffinity=0,
        density=0,
        rgba=[0.75, 0.75, 0.78, 1],
    )
    body.add_geom(
        name=f"{prefix}link_collision", type=mesh, meshname=f"{prefix}link", group=3, density=1200
    )
    body.add_geom(
        name=f"{prefix}skin",
        type=mesh,
        meshname=f"{prefix}skin",
        group=1,
        contype=0,
        conaffinity=0,
        density=0,
        rgba=[0.2, 0.4, 0.9, 1],
    )
    spec.add_sensor(
        name=f"{prefix}tactile",
        type=mujoco.mjtSensor.mjSENS_TACTILE,
        objtype=mujoco.mjtObj.mjOBJ_MESH,
        objname=f"{prefix}skin",
        reftype=mujoco.mjtObj.mjOBJ_GEOM,
        refname=f"{prefix}skin",
    )
    if hinge:
        act = spec.add_actuator(
            name=f"{prefix}mount",
            target=f"{prefix}mount",
            trntype=mujoco.mjtTrn.mjTRN_JOINT,
            ctrlrange=[-0.1, 0.1],
            ctrllimited=True,
        )
        act.set_to_position(kp=2000.0, kv=20.0)
    return body


def link_mesh_file(part: Part) -> str | None:
    """Path of ``part``'s link mesh as an OBJ file, written once per machine and content.

    MuJoCo's compiler caches meshes read from files, not inline ones: a press scene that names
    the link by file compiles in 2-8 ms instead of 20-30 ms, to the same model (the vertices are
    written as the float32 values MuJoCo stores, in order; tests/sim/test_scenes.py compares
    the compiled arrays). None when no temporary folder is writable (the caller inlines it).
    """
    return _mesh_file("link", part.link.vertices, part.link.faces)


def skin_mesh_file(part: Part) -> str | None:
    """Path of ``part``'s sensor mesh (the taxels in layout order) as an OBJ file, as
    `link_mesh_file`: MuJoCo keeps the vertex order, and a cached 1,488-taxel skin compiles in
    0.5 ms instead of 1.7 ms. None when no temporary folder is writable."""
    return _mesh_file("skin", part.layout.positions_m, part.sensor_faces)


def _mesh_file(kind: str, vertices: np.ndarray, faces: np.ndarray) -> str | None:
    verts = np.ascontiguousarray(vertices, dtype=np.float32)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    digest = hashlib.sha256(verts.tobytes() + faces.tobytes()).hexdigest()[:20]
    folder = Path(tempfile.gettempdir()) / f"handskin-meshes-{os.getuid()}"
    path = folder / f"{kind}-{digest}.obj"
    if path.is_file():
        return str(path)
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in verts.astype(float).tolist()]
    lines += [f"f {a} {b} {c}" for a, b, c in (faces + 1).tolist()]
    try:
        folder.mkdir(mode=0o700, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=folder, suffix=".obj.tmp")
        with os.fdopen(fd, "w") as f:
            f.write("\n".join(lines) + "\n")
        os.replace(tmp, path)  # atomic: a concurrent worker reads a whole file or none
    except OSError:
        return None
    return str(path)


def add_contactor(spec: mujoco.MjSpec, c: Contactor, prefix: str = CONTACTOR_PREFIX):
    """Add a contactor body with its slide joint and force motor (names ``obj_<name>``)."""
    name = f"{prefix}{c.name}"
    body = spec.worldbody.add_body(
        name=name, pos=list(c.pos_m), quat=_quat_z_to(-np.asarray(c.press_dir)).tolist()
    )
    body.add_joint(
        name=name,
        type=mujoco.mjtJoint.mjJNT_SLIDE,
        axis=[0, 0, -1],
        range=[-c.travel_m, c.travel_m],
        limited=mujoco.mjtLimited.mjLIMITED_TRUE,
    )
    geom = body.add_geom(
        name=name,
        type=SHAPES[c.shape],
        size=list(c.size_m) + [0.0] * (3 - len(c.size_m)),
        mass=c.mass_kg,
        priority=1,
        rgba=[0.9, 0.5, 0.2, 1],
    )
    if c.solref is not None:
        geom.solref = list(c.solref)
    if c.solimp is not None:
        geom.solimp = list(c.solimp)
    spec.add_actuator(
        name=name,
        target=name,
        trntype=mujoco.mjtTrn.mjTRN_JOINT,
        ctrlrange=[-c.max_force_n, c.max_force_n],
        ctrllimited=True,
    ).set_to_motor()
    return body


def scene_spec(
    part: Part,
    contactors: Sequence[Contactor] = (),
    hinge: bool = False,
    link_file: str | None = None,
) -> mujoco.MjSpec:
    """The scene: options, a light, the part and the contactors (gravity off: forces are the
    commanded ones)."""
    spec = mujoco.MjSpec()
    spec.modelname = f"{part.name}_scene"
    spec.option.timestep = TIMESTEP_S
    spec.option.gravity = [0.0, 0.0, 0.0]
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.worldbody.add_light(name="top", pos=[0, 0, 1.5], dir=[0, 0, -1])
    add_part(spec, part, hinge=hinge, link_file=link_file)
    for c in contactors:
        add_contactor(spec, c)
    return spec


@dataclass(eq=False)
class SkinScene:
    """Owns one compiled scene: model, data, the taxel readout and named accessors."""

    part: Part
    contactors: tuple[Contactor, ...] = ()
    hinge: bool = False
    spec: mujoco.MjSpec = field(init=False)
    model: mujoco.MjModel = field(init=False)
    data: mujoco.MjData = field(init=False)
    readout: TaxelReadout = field(init=False)

    def __post_init__(self) -> None:
        self.contactors = tuple(self.contactors)
        names = [c.name for c in self.contactors]
        if len(set(names)) != len(names):
            raise ConfigError(f"contactor names must be unique; got {names}")
        self.spec = scene_spec(self.part, self.contactors, self.hinge)
        self.model = self.spec.compile()
        self.data = mujoco.MjData(self.model)
        self.readout = TaxelReadout(
            self.model,
            f"{PART_PREFIX}tactile",
            f"{PART_PREFIX}skin",
            [f"{CONTACTOR_PREFIX}{n}" for n in names],
            [c.label for c in self.contactors],
        )
        mujoco.mj_forward(self.model, self.data)

    def forward(self) -> None:
        mujoco.mj_forward(self.model, self.data)

    def step(self, n: int = 1) -> None:
        mujoco.mj_step(self.model, self.data, nstep=n)

    def reset(self) -> None:
        mujoco.mj_resetData(self.model, self.data)
        self.forward()

    def set_force(self, name: str, force_n: float) -> None:
        """Command contactor `name` to push along its press direction with force_n (N)."""
        self.data.actuator(f"{CONTACTOR_PREFIX}{name}").ctrl = force_n

    def contactor_depth_m(self, name: str) -> float:
        """How far contactor `name` has slid from its start along its press direction (m)."""
        return float(self.data.joint(f"{CONTACTOR_PREFIX}{name}").qpos[0])

    def taxel_depth_m(self) -> np.ndarray:
        """(N,) m, layout order."""
        return self.readout.depth_m(self.data)

    def taxel_positions_m(self) -> np.ndarray:
        """(N, 3) m, world, recovered from the sensor geom pose and MuJoCo's recentred mesh."""
        return self.readout.positions_m(self.data)

    def read(self) -> ReadoutFrame:
        """Depth and attribution of the current state."""
        return self.readout.read(self.model, self.data)

    def warnings(self) -> dict[str, int]:
        """MuJoCo warnings raised so far: {warning name: count}, empty when none."""
        return {
            mujoco.mjtWarning(i).name: int(w.number)
            for i, w in enumerate(self.data.warning)
            if w.number
        }
