"""MuJoCo model of a fixed-base Pinocchio model, built with :class:`mujoco.MjSpec`.

The MuJoCo model reproduces the Pinocchio rigid-body dynamics exactly (same joint
placements, axes and inertias; no armature, damping, friction loss or joint limits), so
that the only model mismatch seen by a controller is the one added on purpose: payloads.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import coal
import mujoco
import numpy as np
import pinocchio as pin

from ..robot.collision import CollisionModel, Shape

# MuJoCo rejects moving bodies whose mass or principal inertia is below mjMINVAL (1e-15),
# and a `fullinertia` that is not positive definite. Such bodies (massless intermediate
# links, point masses) get this much mass and isotropic inertia added: safely above
# mjMINVAL, and a relative change of the mass matrix of ~1e-14 (~1e-12) for unit link lengths.
# The inertia's floor is higher: MuJoCo's eigen decomposition of a `fullinertia` refused a point
# mass given 1e-14 (iCub's URDF writes ixx = -5.4e-20 for one).
_MASS_EPS = 1e-14
_INERTIA_EPS = 1e-12

_CAPSULE_RADIUS = 0.03
_CAPSULE_RGBA = (0.7, 0.7, 0.7, 1.0)
_LINK_PRIMITIVE_RGBA = (1.0, 0.55, 0.1, 0.35)  # translucent: the link's own geometry shows through
_OBSTACLE_RGBA = (0.8, 0.2, 0.2, 0.7)
_PLANE_SIZE = (2.0, 2.0, 0.05)  # drawn half-extent; its collisions are unbounded

_MESH_SUFFIXES = (".stl", ".obj")

_HINGE = mujoco.mjtJoint.mjJNT_HINGE
_SLIDE = mujoco.mjtJoint.mjJNT_SLIDE
_JOINT_TYPES: dict[str, tuple[mujoco.mjtJoint, tuple[float, float, float] | None]] = {
    "JointModelRX": (_HINGE, (1.0, 0.0, 0.0)),
    "JointModelRY": (_HINGE, (0.0, 1.0, 0.0)),
    "JointModelRZ": (_HINGE, (0.0, 0.0, 1.0)),
    "JointModelRevoluteUnaligned": (_HINGE, None),
    "JointModelPX": (_SLIDE, (1.0, 0.0, 0.0)),
    "JointModelPY": (_SLIDE, (0.0, 1.0, 0.0)),
    "JointModelPZ": (_SLIDE, (0.0, 0.0, 1.0)),
    "JointModelPrismaticUnaligned": (_SLIDE, None),
}


@dataclass(frozen=True)
class Payload:
    """A rigid mass welded to a Pinocchio frame, present in MuJoCo only.

    Attributes:
        frame: Name of the Pinocchio frame the payload is attached to.
        mass: Mass (kg).
        com: Centre of mass, in the frame (m).
        inertia: Principal inertia about the centre of mass, axes aligned with the frame
            (kg·m²); ``None`` for a point mass.
    """

    frame: str
    mass: float
    com: tuple[float, float, float] = (0.0, 0.0, 0.0)
    inertia: tuple[float, float, float] | None = None


def build_mujoco_model(
    model: pin.Model,
    *,
    timestep: float = 0.001,
    integrator: str = "implicitfast",
    payloads: Sequence[Payload] = (),
    geometry: pin.GeometryModel | None = None,
    scenery: bool = False,
    collision: CollisionModel | None = None,
) -> mujoco.MjModel:
    """MuJoCo model of a fixed-base Pinocchio model with revolute and prismatic joints.

    - One body per Pinocchio joint, named after the joint's child link, placed by
      ``model.jointPlacements`` and carrying ``model.inertias``; ``qpos``/``qvel`` follow
      Pinocchio's ``idx_q``/``idx_v``.
    - No armature, damping, friction loss or joint limits: limits are the controller's job.
    - One ``motor`` actuator per joint, named like the joint, gear 1 and no control clamp:
      ``data.ctrl`` is the joint torque (or force).
    - One site per Pinocchio ``BODY`` or ``OP_FRAME`` frame, named like the frame.
    - ``payloads`` are welded bodies that Pinocchio does not know about.
    - ``geometry`` (a Pinocchio collision or visual model) gives the geoms: primitives and
      STL/OBJ meshes, other meshes (``.dae``) are skipped; without it, capsules join
      consecutive joint origins. Geoms never collide (contype = conaffinity = 0).
    - ``scenery`` adds what a viewer or a video needs and the dynamics ignore: a
      non-colliding checkered floor at z = 0, a light and a sky.
    - ``collision`` adds the collision primitives of the links and the obstacles as geoms
      that collide only in the watched pairs (explicit contact pairs): a violation of the
      controller's distance bounds becomes a contact, as it would be on the robot.

    Args:
        model: Fixed-base Pinocchio model.
        timestep: Simulation time step (s).
        integrator: ``"euler"``, ``"rk4"``, ``"implicit"`` or ``"implicitfast"``.
        payloads: Masses added to the MuJoCo model only.
        geometry: Geometry to display; mesh paths as resolved by Pinocchio's loaders.
        scenery: Add a floor, a light and a sky for rendering.
        collision: The spec's collision model (limits.collision), resolved.

    Raises:
        ValueError: On a joint that is neither revolute nor prismatic, an unknown
            integrator or payload frame, or a joint order MuJoCo cannot reproduce.
    """
    spec = mujoco.MjSpec()
    spec.modelname = model.name
    # Bodies carry the Pinocchio inertias; geoms must not add mass.
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    # Principal moments that break A + B ≥ C (CAD rounding) are evened out instead of refused
    # (validation warns: the controller keeps the URDF's)
    spec.compiler.balanceinertia = True
    spec.option.timestep = timestep
    spec.option.integrator = _integrator(integrator)
    spec.option.gravity = model.gravity.linear

    bodies: list[mujoco.MjsBody] = [spec.worldbody]
    for i in range(1, model.njoints):
        parent = bodies[model.parents[i]]
        pos, quat = _pos_quat(model.jointPlacements[i])
        body = parent.add_body(name=_body_name(model, i), pos=pos, quat=quat)
        joint_type, axis = _joint_type_and_axis(model.joints[i])
        body.add_joint(
            name=model.names[i],
            type=joint_type,
            axis=axis,
            limited=mujoco.mjtLimited.mjLIMITED_FALSE,
            armature=0.0,
            damping=0.0,
            frictionloss=0.0,
        )
        _set_inertial(body, model.inertias[i])
        spec.add_actuator(
            name=model.names[i],
            target=model.names[i],
            trntype=mujoco.mjtTrn.mjTRN_JOINT,
            gear=[1.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            ctrllimited=mujoco.mjtLimited.mjLIMITED_FALSE,
            forcelimited=mujoco.mjtLimited.mjLIMITED_FALSE,
        )
        bodies.append(body)

    for frame in model.frames:
        if frame.type in (pin.FrameType.OP_FRAME, pin.FrameType.BODY):
            pos, quat = _pos_quat(frame.placement)
            bodies[frame.parentJoint].add_site(name=frame.name, pos=pos, quat=quat)

    for k, payload in enumerate(payloads):
        _add_payload(model, bodies, payload, f"payload_{k}")

    if geometry is None:
        _add_capsules(model, bodies)
    else:
        _add_geometry(spec, geometry, bodies)
    if collision is not None:
        _add_collision(spec, model, bodies, collision)
    if scenery:
        _add_scenery(spec)
    mj_model = spec.compile()
    _check_joint_order(model, mj_model)
    return mj_model


def mass_matrix(mj_model: mujoco.MjModel, mj_data: mujoco.MjData, q: np.ndarray) -> np.ndarray:
    """Dense joint-space mass matrix at ``q`` (sets ``mj_data.qpos``)."""
    mj_data.qpos[:] = q
    mujoco.mj_fwdPosition(mj_model, mj_data)
    M = np.zeros((mj_model.nv, mj_model.nv))
    # MuJoCo 4 takes mjData as second argument (MuJoCo 3 took d.qM as third).
    mujoco.mj_fullM(mj_model, mj_data, M)
    return M


def bias_forces(
    mj_model: mujoco.MjModel, mj_data: mujoco.MjData, q: np.ndarray, dq: np.ndarray
) -> np.ndarray:
    """Coriolis, centrifugal and gravity forces at ``(q, dq)`` (sets ``qpos``, ``qvel``)."""
    mj_data.qpos[:] = q
    mj_data.qvel[:] = dq
    mujoco.mj_fwdPosition(mj_model, mj_data)
    mujoco.mj_fwdVelocity(mj_model, mj_data)
    return mj_data.qfrc_bias.copy()


def _integrator(name: str) -> mujoco.mjtIntegrator:
    choices = ("euler", "rk4", "implicit", "implicitfast")
    if name not in choices:
        raise ValueError(f"unknown integrator {name!r}; choose one of {', '.join(choices)}")
    return mujoco.mjtIntegrator.__members__[f"mjINT_{name.upper()}"]


def _pos_quat(placement: pin.SE3) -> tuple[np.ndarray, np.ndarray]:
    x, y, z, w = pin.Quaternion(placement.rotation).coeffs()
    return placement.translation.copy(), np.array([w, x, y, z])


def _body_name(model: pin.Model, joint_id: int) -> str:
    """Name of the joint's first child link, or of the joint if it has none."""
    for frame in model.frames:
        if frame.type == pin.FrameType.BODY and frame.parentJoint == joint_id:
            return frame.name
    return model.names[joint_id]


def _joint_type_and_axis(joint: pin.JointModel) -> tuple[mujoco.mjtJoint, np.ndarray]:
    name = joint.shortname()
    if name not in _JOINT_TYPES:
        raise ValueError(
            f"unsupported joint type {name}: only revolute and prismatic joints of a fixed-base model"
        )
    joint_type, axis = _JOINT_TYPES[name]
    return joint_type, np.array(joint.extract().axis if axis is None else axis)


def _set_inertial(body: mujoco.MjsBody, inertia: pin.Inertia) -> None:
    rot = inertia.inertia
    if np.linalg.eigvalsh(rot)[0] < _INERTIA_EPS:
        rot = rot + _INERTIA_EPS * np.eye(3)
    body.mass = max(inertia.mass, _MASS_EPS)
    body.ipos = inertia.lever
    body.fullinertia = [rot[0, 0], rot[1, 1], rot[2, 2], rot[0, 1], rot[0, 2], rot[1, 2]]
    body.explicitinertial = True


def _add_payload(model: pin.Model, bodies: list[mujoco.MjsBody], payload: Payload, name: str) -> None:
    if not model.existFrame(payload.frame):
        raise ValueError(f"payload frame {payload.frame!r} is not in the model")
    frame = model.frames[model.getFrameId(payload.frame)]
    pos, quat = _pos_quat(frame.placement)
    # Welded bodies may be point masses: only moving bodies need a positive inertia.
    bodies[frame.parentJoint].add_body(
        name=name,
        pos=pos,
        quat=quat,
        mass=payload.mass,
        ipos=payload.com,
        inertia=(0.0, 0.0, 0.0) if payload.inertia is None else payload.inertia,
        explicitinertial=True,
    )


def _add_capsules(model: pin.Model, bodies: list[mujoco.MjsBody]) -> None:
    """Capsules from each body origin to its child joints, or to its frames at the tip."""
    for i, body in enumerate(bodies):
        tips = [
            model.jointPlacements[child].translation
            for child in range(1, model.njoints)
            if model.parents[child] == i
        ]
        if not tips:
            tips = [
                f.placement.translation
                for f in model.frames
                if f.parentJoint == i and f.type in (pin.FrameType.OP_FRAME, pin.FrameType.BODY)
            ]
        for tip in tips:
            # Segments shorter than the radius would only draw a ball at the body origin.
            if np.linalg.norm(tip) > _CAPSULE_RADIUS:
                body.add_geom(
                    type=mujoco.mjtGeom.mjGEOM_CAPSULE,
                    fromto=np.concatenate([np.zeros(3), tip]),
                    size=[_CAPSULE_RADIUS, 0.0, 0.0],
                    rgba=_CAPSULE_RGBA,
                    contype=0,
                    conaffinity=0,
                )


def _add_geometry(spec: mujoco.MjSpec, geometry: pin.GeometryModel, bodies: list[mujoco.MjsBody]) -> None:
    """Primitives and STL/OBJ meshes of a Pinocchio geometry model, as non-colliding geoms."""
    for obj in geometry.geometryObjects:
        shape = obj.geometry
        mesh_path = Path(obj.meshPath) if obj.meshPath else None
        kwargs: dict[str, object]
        if isinstance(shape, coal.Box):
            kwargs = {"type": mujoco.mjtGeom.mjGEOM_BOX, "size": shape.halfSide}
        elif isinstance(shape, coal.Sphere):
            kwargs = {"type": mujoco.mjtGeom.mjGEOM_SPHERE, "size": [shape.radius, 0.0, 0.0]}
        elif isinstance(shape, coal.Cylinder):
            kwargs = {"type": mujoco.mjtGeom.mjGEOM_CYLINDER, "size": [shape.radius, shape.halfLength, 0.0]}
        elif isinstance(shape, coal.Capsule):
            kwargs = {"type": mujoco.mjtGeom.mjGEOM_CAPSULE, "size": [shape.radius, shape.halfLength, 0.0]}
        elif mesh_path is not None and mesh_path.suffix.lower() in _MESH_SUFFIXES:
            # The mesh volume is never used for inertia; "shell" also accepts open meshes.
            spec.add_mesh(
                name=obj.name,
                file=str(mesh_path),
                scale=obj.meshScale,
                inertia=mujoco.mjtMeshInertia.mjMESH_INERTIA_SHELL,
            )
            kwargs = {"type": mujoco.mjtGeom.mjGEOM_MESH, "meshname": obj.name}
        else:
            continue
        pos, quat = _pos_quat(obj.placement)
        bodies[obj.parentJoint].add_geom(
            name=obj.name, pos=pos, quat=quat, rgba=obj.meshColor, contype=0, conaffinity=0, **kwargs
        )


def _add_collision(spec: mujoco.MjSpec, model: pin.Model, bodies: list[mujoco.MjsBody], collision: CollisionModel) -> None:
    """The primitives as geoms (named collision_<body>_<k>) and one contact pair per two primitives of a
    watched pair; the geoms collide with nothing else (contype = conaffinity = 0)."""
    names: dict[str, list[str]] = {}
    for body in (*collision.links, *collision.obstacles):
        if body.frame is None:
            parent, placement, rgba = spec.worldbody, pin.SE3.Identity(), _OBSTACLE_RGBA
        else:
            frame = model.frames[model.getFrameId(body.frame)]
            parent, placement, rgba = bodies[frame.parentJoint], frame.placement, _LINK_PRIMITIVE_RGBA
        names[body.name] = []
        for k, shape in enumerate(body.shapes):
            name = f"collision_{body.name}_{k}"
            parent.add_geom(name=name, rgba=rgba, contype=0, conaffinity=0, **_geom(shape, placement))
            names[body.name].append(name)
    for pair in collision.pairs:
        for a in names[pair.a.name]:
            for b in names[pair.b.name]:
                spec.add_pair(geomname1=a, geomname2=b)


def _geom(shape: Shape, placement: pin.SE3) -> dict[str, object]:
    """MjSpec geom attributes of a shape given in a frame placed at `placement` in the body."""
    if shape.swept:
        start, end = placement.act(shape.start), placement.act(shape.end)
        if shape.kind == "sphere":
            return {"type": mujoco.mjtGeom.mjGEOM_SPHERE, "pos": start, "size": [shape.radius, 0.0, 0.0]}
        return {"type": mujoco.mjtGeom.mjGEOM_CAPSULE, "fromto": np.concatenate([start, end]),
                "size": [shape.radius, 0.0, 0.0]}
    if shape.kind == "box":
        pos, quat = _pos_quat(placement * pin.SE3(shape.rotation, shape.start))
        return {"type": mujoco.mjtGeom.mjGEOM_BOX, "pos": pos, "quat": quat, "size": shape.half}
    # a plane's geom is its z axis: rotate z onto the normal
    rotation = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), shape.normal).matrix()
    pos, quat = _pos_quat(placement * pin.SE3(rotation, shape.start))
    return {"type": mujoco.mjtGeom.mjGEOM_PLANE, "pos": pos, "quat": quat, "size": list(_PLANE_SIZE)}


def _add_scenery(spec: mujoco.MjSpec) -> None:
    """A checkered floor (no collisions), a light from above and a gradient sky."""
    spec.add_texture(
        name="sky", type=mujoco.mjtTexture.mjTEXTURE_SKYBOX, builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT,
        rgb1=[0.55, 0.7, 0.85], rgb2=[0.1, 0.12, 0.15], width=256, height=256,
    )
    spec.add_texture(
        name="floor", type=mujoco.mjtTexture.mjTEXTURE_2D, builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER,
        rgb1=[0.32, 0.34, 0.36], rgb2=[0.24, 0.26, 0.28], width=256, height=256,
    )
    material = spec.add_material(name="floor", texrepeat=[8, 8], reflectance=0.1)
    material.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "floor"
    spec.worldbody.add_geom(
        name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[3.0, 3.0, 0.05], material="floor",
        contype=0, conaffinity=0,
    )
    spec.worldbody.add_light(name="sun", pos=[0.5, -0.5, 3.0], dir=[-0.1, 0.1, -1.0], castshadow=True)


def _check_joint_order(model: pin.Model, mj_model: mujoco.MjModel) -> None:
    """MuJoCo numbers dofs depth-first; Pinocchio models built by hand need not."""
    for i in range(1, model.njoints):
        if mj_model.joint(model.names[i]).qposadr[0] != model.joints[i].idx_q:
            raise ValueError(
                f"joint {model.names[i]!r}: Pinocchio joints are not in depth-first order, "
                "MuJoCo's qpos would not follow idx_q"
            )
