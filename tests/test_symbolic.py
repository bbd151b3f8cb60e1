"""SymbolicRobot and the symbolic linear algebra against Pinocchio's numeric algorithms."""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest

from dcts_spec.robot.builtin import example_robot_data_dir, load_builtin_model, random_configuration
from dcts_spec.symbolic import SymbolicRobot
from dcts_spec.symbolic.linalg import (cholesky, cholesky_solve, looped_products, product, spd_inverse, symmetric_product,
                                       triangular_inverse)

N_STATES = 100
TOL = 1e-9


def _ur5() -> pin.Model:
    return pin.buildModelFromUrdf(str(example_robot_data_dir() / "ur_description/urdf/ur5_robot.urdf"))


def _tree() -> pin.Model:
    """A branching model with every supported joint type, random geometry and inertias, tilted gravity."""
    rng = np.random.default_rng(7)

    def placement() -> pin.SE3:
        return pin.SE3(pin.rpy.rpyToMatrix(*rng.uniform(-np.pi, np.pi, 3)), rng.normal(scale=0.3, size=3))

    def unit() -> np.ndarray:
        a = rng.normal(size=3)
        return a / np.linalg.norm(a)

    joints = [
        pin.JointModelRX(),
        pin.JointModelRY(),
        pin.JointModelRZ(),
        pin.JointModelRevoluteUnaligned(unit()),
        pin.JointModelPX(),
        pin.JointModelPY(),
        pin.JointModelPZ(),
        pin.JointModelPrismaticUnaligned(unit()),
    ]
    parents = [0, 1, 2, 3, 2, 5, 6, 1]  # branches at joints 1 and 2
    model = pin.Model()
    for k, (jmodel, parent) in enumerate(zip(joints, parents, strict=True)):
        jid = model.addJoint(parent, jmodel, placement(), f"j{k}")
        rot = pin.rpy.rpyToMatrix(*rng.uniform(-np.pi, np.pi, 3))
        inertia = rot @ np.diag(rng.uniform(0.01, 0.1, 3)) @ rot.T
        body = pin.Inertia(rng.uniform(0.5, 3.0), rng.normal(scale=0.1, size=3), inertia)
        model.appendBodyToJoint(jid, body, pin.SE3.Identity())
        model.addFrame(pin.Frame(f"f{k}", jid, placement(), pin.FrameType.OP_FRAME))
    model.lowerPositionLimit = -np.pi * np.ones(model.nq)
    model.upperPositionLimit = np.pi * np.ones(model.nq)
    model.gravity = pin.Motion(np.array([1.5, -2.0, -9.0]), np.zeros(3))
    return model


@dataclass(frozen=True)
class Robot:
    load: Callable[[], pin.Model]
    end_frame: str  # must be among the tested end-of-chain frames
    mid_frame: str


ROBOTS = {
    "iiwa14": Robot(lambda: load_builtin_model("iiwa14"), "tool", "link4"),
    "panda": Robot(lambda: load_builtin_model("panda"), "panda_hand_tcp", "panda_link4"),
    "ur5": Robot(_ur5, "tool0", "forearm_link"),
    "tree": Robot(_tree, "f3", "f1"),
}


def _tested_frames(model: pin.Model, robot: Robot) -> list[str]:
    """BODY/OP_FRAME frames on the leaves of the kinematic tree, and one mid-chain frame."""
    leaves = set(range(1, model.njoints)) - set(model.parents[1:])
    ends = [
        f.name
        for f in model.frames
        if f.type in (pin.FrameType.BODY, pin.FrameType.OP_FRAME) and f.parentJoint in leaves
    ]
    assert robot.end_frame in ends
    return [*ends, robot.mid_frame]


def _reference(model: pin.Model, frames: list[str], q: np.ndarray, dq: np.ndarray, ddq: np.ndarray) -> dict:
    """Every tested quantity from Pinocchio's numeric algorithms."""
    data = model.createData()
    out: dict[str, np.ndarray] = {}
    pin.framesForwardKinematics(model, data, q)
    pin.computeJointJacobians(model, data, q)
    for name in frames:
        fid = model.getFrameId(name)
        out[f"p/{name}"] = data.oMf[fid].translation.reshape(3, 1)
        out[f"R/{name}"] = data.oMf[fid].rotation
        out[f"J/{name}"] = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)
    pin.forwardKinematics(model, data, q, dq, np.zeros(model.nv))
    for name in frames:
        acc = pin.getFrameClassicalAcceleration(model, data, model.getFrameId(name), pin.LOCAL_WORLD_ALIGNED)
        out[f"dJdq/{name}"] = acc.vector.reshape(6, 1)
    mass = pin.crba(model, data, q)
    out["M"] = np.triu(mass) + np.triu(mass, 1).T  # crba fills the upper triangle only
    out["Minv"] = np.triu(minv := pin.computeMinverse(model, data, q)) + np.triu(minv, 1).T
    out["g"] = pin.computeGeneralizedGravity(model, data, q).reshape(-1, 1)
    out["dg"] = np.diag(pin.computeGeneralizedGravityDerivatives(model, data, q)).reshape(-1, 1).copy()
    out["nu"] = pin.rnea(model, data, q, dq, np.zeros(model.nv)).reshape(-1, 1) - out["g"]
    out["tau"] = pin.rnea(model, data, q, dq, ddq).reshape(-1, 1)
    return out


@pytest.fixture(scope="module", params=list(ROBOTS))
def evaluated(request: pytest.FixtureRequest) -> tuple[str, dict[str, tuple[np.ndarray, np.ndarray]]]:
    """(robot, {quantity: (symbolic, reference)}), each stacked side by side over N_STATES random states."""
    robot = ROBOTS[request.param]
    model = robot.load()
    frames = _tested_frames(model, robot)
    sym = SymbolicRobot(model)
    ddq = ca.SX.sym("ddq", model.nv)
    outputs: dict[str, ca.SX] = {}
    for name in frames:
        outputs[f"p/{name}"], outputs[f"R/{name}"] = sym.frame_placement(name)
        outputs[f"J/{name}"] = sym.frame_jacobian(name)
        outputs[f"dJdq/{name}"] = sym.frame_bias_acceleration(name)
    outputs |= {
        "M": sym.mass_matrix(),
        "Minv": spd_inverse(sym.mass_matrix()),
        "nu": sym.coriolis(),
        "g": sym.gravity(),
        "dg": sym.gravity_rate(),
        "tau": sym.inverse_dynamics(ddq),
    }
    fun = ca.Function("all", [sym.q, sym.dq, ddq], list(outputs.values()), ["q", "dq", "ddq"], list(outputs))

    rng = np.random.default_rng(2024)
    qs = np.stack([random_configuration(model, rng, margin=0.0) for _ in range(N_STATES)], axis=1)
    dqs, ddqs = rng.normal(size=(2, model.nv, N_STATES))
    values = fun.map(N_STATES)(q=qs, dq=dqs, ddq=ddqs)
    refs = [_reference(model, frames, qs[:, k], dqs[:, k], ddqs[:, k]) for k in range(N_STATES)]
    return request.param, {key: (np.array(values[key]), np.hstack([r[key] for r in refs])) for key in outputs}


def _check(evaluated: tuple[str, dict], prefix: str) -> None:
    robot, results = evaluated
    keys = [k for k in results if k.split("/")[0] == prefix]
    assert keys
    for key in keys:
        sym, ref = results[key]
        assert sym.shape == ref.shape, key
        err = np.max(np.abs(sym - ref))
        assert err <= TOL * max(1.0, np.max(np.abs(ref))), f"{robot} {key}: max error {err:.2e}"


def test_frame_position(evaluated: tuple[str, dict]) -> None:
    _check(evaluated, "p")


def test_frame_rotation(evaluated: tuple[str, dict]) -> None:
    _check(evaluated, "R")


def test_frame_jacobian(evaluated: tuple[str, dict]) -> None:
    _check(evaluated, "J")


def test_frame_bias_acceleration(evaluated: tuple[str, dict]) -> None:
    _check(evaluated, "dJdq")


def test_mass_matrix(evaluated: tuple[str, dict]) -> None:
    _check(evaluated, "M")


def test_coriolis(evaluated: tuple[str, dict]) -> None:
    _check(evaluated, "nu")


def test_gravity(evaluated: tuple[str, dict]) -> None:
    _check(evaluated, "g")


def test_gravity_rate(evaluated: tuple[str, dict]) -> None:
    """∂g_j/∂q_j, from the subtrees' first moments (what the joints' braking averages gravity with)."""
    _check(evaluated, "dg")


def test_gravity_along_a_revolute_joint_is_the_sinusoid_of_its_rate() -> None:
    """g_j(q + θ e_j) = g_j cos θ + (∂g_j/∂q_j) sin θ for a revolute joint, the others fixed:
    Pinocchio's gravity at turned configurations against the closed form the braking uses."""
    model = load_builtin_model("panda")
    data = model.createData()
    sym = SymbolicRobot(model)
    rate = ca.Function("rate", [sym.q], [sym.gravity_rate()])
    rng = np.random.default_rng(7)
    for _ in range(5):
        q = random_configuration(model, rng, margin=0.0)
        g, dg = pin.computeGeneralizedGravity(model, data, q).copy(), np.array(rate(q)).ravel()
        for j in range(model.nv):
            for theta in rng.uniform(-3.0, 3.0, size=3):
                turned = q.copy()
                turned[j] += theta
                expected = g[j] * np.cos(theta) + dg[j] * np.sin(theta)
                assert pin.computeGeneralizedGravity(model, data, turned)[j] == pytest.approx(expected, abs=1e-9)


def test_inverse_dynamics(evaluated: tuple[str, dict]) -> None:
    _check(evaluated, "tau")


def test_mass_matrix_inverse(evaluated: tuple[str, dict]) -> None:
    _check(evaluated, "Minv")


def test_shared_expressions_are_built_once() -> None:
    sym = SymbolicRobot(load_builtin_model("panda"))
    fid = sym.model.getFrameId("panda_hand_tcp")
    assert sym.mass_matrix() is sym.mass_matrix()
    assert sym.coriolis() is sym.coriolis()
    assert sym.gravity() is sym.gravity()
    assert sym.frame_jacobian("panda_hand_tcp") is sym.frame_jacobian(fid)
    assert sym.frame_bias_acceleration("panda_hand_tcp") is sym.frame_bias_acceleration(fid)
    assert sym.frame_placement("panda_hand_tcp")[0] is sym.frame_placement(fid)[0]


def test_given_symbols_are_used() -> None:
    model = load_builtin_model("panda")
    q, dq = ca.SX.sym("x", model.nq), ca.SX.sym("v", model.nv)
    sym = SymbolicRobot(model, q, dq)
    assert sym.q is q and sym.dq is dq and sym.nv == model.nv
    assert set(ca.symvar(sym.coriolis())) <= set(ca.symvar(ca.vertcat(q, dq)))
    with pytest.raises(ValueError, match="shape"):
        SymbolicRobot(model, ca.SX.sym("q", model.nq + 1))


@pytest.mark.parametrize(
    ("joint", "kind"),
    [(pin.JointModelRUBZ(), "JointModelRUBZ"), (pin.JointModelFreeFlyer(), "JointModelFreeFlyer")],
)
def test_unsupported_joint_is_named(joint: pin.JointModel, kind: str) -> None:
    model = pin.Model()
    first = model.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "shoulder")
    model.addJoint(first, joint, pin.SE3.Identity(), "wrist")
    with pytest.raises(ValueError, match=f"'wrist'.*{kind}"):
        SymbolicRobot(model)


def test_unknown_frame() -> None:
    sym = SymbolicRobot(load_builtin_model("panda"))
    with pytest.raises(KeyError):
        sym.frame_jacobian("no_such_frame")


def test_symmetric_product_is_the_product_at_half_the_operations() -> None:
    """aᵀ(M a) and GᵀG from their lower triangles: the same numbers as numpy's product, exactly
    symmetric, and a little over half of mtimes' operations."""
    rng = np.random.default_rng(5)
    n, k = 7, 9
    a, m = ca.SX.sym("a", n, k), ca.SX.sym("m", n, n)
    m_sym = (m + m.T) / 2
    products = [symmetric_product(a, ca.mtimes(m_sym, a)), symmetric_product(a, a)]
    fun = ca.Function("sym", [a, m], products)
    a_num, m_num = rng.normal(size=(n, k)), rng.normal(size=(n, n))
    m_num = m_num + m_num.T
    energy, gram = (np.array(v) for v in fun(a_num, m_num))
    for value, expected in ((energy, a_num.T @ m_num @ a_num), (gram, a_num.T @ a_num)):
        assert np.array_equal(value, value.T)
        assert np.allclose(value, expected, rtol=0, atol=1e-12)
    full = ca.Function("full", [a], [ca.mtimes(a.T, a)], {"cse": True}).n_instructions()
    half = ca.Function("half", [a], [symmetric_product(a, a)], {"cse": True}).n_instructions()
    assert half < 0.65 * full, (half, full)  # (both count the 63 inputs and 81 outputs too)
    with pytest.raises(ValueError, match="same shape"):
        symmetric_product(a, ca.SX.sym("b", n, k + 1))


def test_looped_products_are_kernel_calls_with_the_same_numbers() -> None:
    """Within looped_products, a large product or Gram matrix is a call to one MX kernel (its
    arithmetic is not in the caller's instructions, and CasADi emits the kernel once), with the
    unrolled product's numbers bit for bit and its structural zeros; a small one stays unrolled."""
    rng = np.random.default_rng(6)
    n, k = 9, 12
    a, b = ca.SX.sym("a", n, k), ca.SX.sym("b", k, n)
    a_sparse = ca.project(a, ca.DM(np.tril(np.ones((n, k)))).sparsity())  # (structural zeros, as a tree's M has)
    small = ca.SX.sym("s", 2, 2)
    expressions = lambda: [product(a_sparse, b), symmetric_product(b, b), product(small, small)]  # noqa: E731
    unrolled = ca.Function("unrolled", [a, b, small], expressions())
    with looped_products():
        looped = ca.Function("looped", [a, b, small], expressions())
    plain = ca.Function("plain", [a, b], [product(a, b)]).n_instructions()  # (outside: the plain product)
    assert plain == ca.Function("mtimes", [a, b], [ca.mtimes(a, b)]).n_instructions()
    assert looped.n_instructions() < 0.2 * unrolled.n_instructions()
    inputs = [rng.normal(size=(n, k)), rng.normal(size=(k, n)), rng.normal(size=(2, 2))]
    for mine, theirs in zip(looped(*inputs), unrolled(*inputs)):
        assert mine.sparsity() == theirs.sparsity()
        assert np.array_equal(np.array(mine), np.array(theirs))
    source = ca.CodeGenerator("looped.c")
    source.add(looped)
    text = source.dump()
    assert len(re.findall(r"^static int casadi_f\d+\(", text, re.M)) == 3  # (the caller and two kernels)
    assert len(re.findall(r"^\s+casadi_mtimes(_dense)?\(", text, re.M)) == 2  # (their loops, called)


def test_cholesky_factors_and_solves() -> None:
    rng = np.random.default_rng(3)
    n = 6
    a = ca.SX.sym("a", n, n)
    b = ca.SX.sym("b", n, 2)
    low = cholesky(a)
    fun = ca.Function("chol", [a, b], [low, cholesky_solve(low, b), triangular_inverse(low), spd_inverse(a)])
    root = rng.normal(size=(n, n))
    a_num = root @ root.T + n * np.eye(n)
    b_num = rng.normal(size=(n, 2))
    low_num, x, low_inv, a_inv = (np.array(v) for v in fun(a_num, b_num))
    assert np.allclose(np.triu(low_num, 1), 0.0)
    assert np.allclose(low_num @ low_num.T, a_num, rtol=0, atol=1e-12)
    assert np.allclose(a_num @ x, b_num, rtol=0, atol=1e-12)
    assert np.allclose(low_inv @ low_num, np.eye(n), rtol=0, atol=1e-12)
    assert np.array_equal(a_inv, a_inv.T)
    assert np.allclose(a_inv, np.linalg.inv(a_num), rtol=0, atol=1e-12)
