"""Redundant bilateral constraints in 3D, the cases of multibody practice: a
door on two coaxial hinges moves as on one, and a planar four-bar linkage
built in 3D (four revolute joints with parallel axes, a closed loop whose
out-of-plane rows repeat each other: Grübler counts -2 degrees of freedom,
it has 1) moves as the same linkage built in 2D, on the crank-rocker
relation of its geometry."""

import warnings

import jax
import numpy as np
import pytest

import nsga_jax as nj
from nsga_jax._models.redundancy import RedundantConstraintsWarning, bilateral_redundancy
from nsga_jax.system import Pin, Revolute, RigidBody2D, RigidBody3D, System

H = 1e-3


def rot_z(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rot_y(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def run(system: System, t_end: float):
    model, q0, v0 = system.build()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RedundantConstraintsWarning)
        sol = nj.simulate(model, nj.DS(), 0.0, t_end, H, q0, v0)
    assert sol.stats["failed_steps"] == 0
    return model, sol


def max_violation(sol) -> float:
    """The largest bilateral violation of a run, positions [m] and velocities [m/s]."""
    return float(max(np.abs(np.asarray(sol.records.bilateral)).max(),
                     np.abs(np.asarray(sol.records.bilateral_rate)).max()))


# -- a door on two hinges ---------------------------------------------------------------------------------------

TILT, WIDTH, HEIGHT, OPEN, SPIN = 0.3, 0.8, 2.0, 0.8, 1.0  # rad, m, m, rad, rad/s
HINGES_AT = (0.8, -0.8)  # m, along the hinge line from the door's mid-height


def door(hinges: int) -> System:
    """A 20 kg door (0.04 x 0.8 x 2 m) on ``hinges`` coaxial hinges whose
    line (through the origin) leans by TILT from the vertical, so that
    gravity closes it; released OPEN about the hinge line, turning at SPIN.
    Body frame: x across the door, y along its width (the hinges at y =
    -WIDTH/2), z along the hinge line."""
    lean, turn = rot_y(TILT), rot_z(OPEN)
    R0, axis = lean @ turn, lean @ np.array([0.0, 0.0, 1.0])
    r0, w0 = R0 @ np.array([0.0, WIDTH / 2, 0.0]), SPIN * axis
    m, sides = 20.0, np.array([0.04, WIDTH, HEIGHT])
    inertia = m / 12 * (sides @ sides - sides**2)  # a box's principal moments
    s = System(dim=3, gravity=[0.0, 0.0, -9.81])
    s.add_body("door", RigidBody3D(m, inertia, position=r0, rotation=R0, velocity=np.cross(w0, r0),
                                   angular_velocity=w0))
    for i, z in enumerate(HINGES_AT[:hinges]):
        s.add_joint(f"hinge{i}", Revolute("ground", "door", axis=axis, axis_b=[0.0, 0.0, 1.0], at_a=z * axis,
                                          at_b=[0.0, -WIDTH / 2, z]))
    return s


def test_the_second_hinge_of_a_door_is_reported_by_name():
    model, q0, _ = door(2).build()
    report = bilateral_redundancy(model, q0)
    # 6 rigidity rows and 2 x 5 hinge rows on 12 coordinates, 1 degree of freedom: rank 11; the whole second
    # hinge repeats the first (its point is on the first's axis)
    assert (report.n_rows, report.rank, report.n_redundant) == (16, 11, 5)
    assert report.redundant == tuple(f"joints.hinge1[{i}]" for i in range(5))
    assert {"joints.hinge0", "joints.hinge1"} <= set(report.parts)
    assert bilateral_redundancy(*door(1).build()[:2]) is None


def test_a_door_on_two_hinges_swings_as_on_one():
    t_end = 0.3
    model, two = run(door(2), t_end)
    _, one = run(door(1), t_end)
    np.testing.assert_allclose(two.q, one.q, atol=1e-9)
    np.testing.assert_allclose(two.v, one.v, atol=1e-8)
    assert max_violation(two) < 1e-9
    # it turns about the hinge line alone, and gravity has turned it back a good part of the way
    body, axis = model.body("door"), rot_y(TILT)[:, 2]
    omega = np.asarray(jax.vmap(body.angular_velocity)(two.q, two.v))
    assert np.abs(np.cross(omega, axis)).max() < 1e-9 * np.abs(omega).max()
    width = rot_y(TILT).T @ np.asarray(two.q[:, 6:9]).T  # the door's y axis, in the hinge frame
    angle = np.arctan2(-width[0], width[1])
    assert abs(angle[0] - OPEN) < 1e-12
    assert angle.max() - angle.min() > 0.1


# -- a planar four-bar built in 3D --------------------------------------------------------------------------------

CRANK, COUPLER, ROCKER, BASE = 0.3, 1.0, 0.8, 0.9  # m: a Grashof crank-rocker (0.3 + 1.0 < 0.8 + 0.9)
MASS = {"crank": 0.5, "coupler": 1.2, "rocker": 1.0}  # kg
THICK = 0.05  # m: the rods' square section


def loop_points(crank_angle: float) -> tuple[np.ndarray, ...]:
    """The joints A (ground-crank), B (crank-coupler), C (coupler-rocker),
    D (rocker-ground) at a crank angle, C on the upper branch: the loop's
    closed-form position."""
    A, D = np.zeros(2), np.array([BASE, 0.0])
    B = CRANK * np.array([np.cos(crank_angle), np.sin(crank_angle)])
    e = D - B
    dist = np.linalg.norm(e)
    along = (COUPLER**2 - ROCKER**2 + dist**2) / (2 * dist)
    C = B + (along * e + np.sqrt(COUPLER**2 - along**2) * np.array([-e[1], e[0]])) / dist
    return A, B, C, D


def rocker_angle(crank_angle: float) -> float:
    _, _, C, D = loop_points(crank_angle)
    return float(np.arctan2(C[1] - D[1], C[0] - D[0]))


def four_bar(dim: int, crank_angle: float = 1.2) -> System:
    """Three uniform rods (THICK square) on four joints in the plane z = 0,
    released at rest under gravity -y: Pins in 2D, Revolutes about z in 3D.
    Each rod's body x axis runs from its first joint to its second."""
    A, B, C, D = loop_points(crank_angle)
    ends = {"crank": (A, B), "coupler": (B, C), "rocker": (D, C)}
    s = System(dim=dim, gravity=[0.0, -9.81, 0.0][:dim])
    half = {}
    for name, (p, q) in ends.items():
        length, angle = np.linalg.norm(q - p), np.arctan2(q[1] - p[1], q[0] - p[0])
        half[name] = length / 2
        m = MASS[name]
        inertia = m / 12 * np.array([2 * THICK**2, length**2 + THICK**2, length**2 + THICK**2])  # a square rod's
        if dim == 2:
            s.add_body(name, RigidBody2D(m, inertia[2], position=(p + q) / 2, angle=angle))
        else:
            s.add_body(name, RigidBody3D(m, inertia, position=[*(p + q) / 2, 0.0], rotation=rot_z(angle)))

    def at(x: float) -> list[float]:
        return [x, 0.0, 0.0][:dim]

    for name, a, b, at_a, at_b in (("A", "ground", "crank", at(0.0), at(-half["crank"])),
                                   ("B", "crank", "coupler", at(half["crank"]), at(-half["coupler"])),
                                   ("C", "coupler", "rocker", at(half["coupler"]), at(half["rocker"])),
                                   ("D", "ground", "rocker", at(BASE), at(-half["rocker"]))):
        joint = Pin(a, b, at_a=at_a, at_b=at_b) if dim == 2 else Revolute(a, b, axis=[0.0, 0.0, 1.0], at_a=at_a,
                                                                          at_b=at_b)
        s.add_joint(name, joint)
    return s


def test_the_out_of_plane_rows_of_the_closing_joint_are_reported():
    model, q0, _ = four_bar(3).build()
    report = bilateral_redundancy(model, q0)
    # 3 x 6 rigidity rows and 4 x 5 joint rows on 36 coordinates, 1 degree of freedom: rank 35; the loop's last
    # joint repeats the out-of-plane translation and the two tilts the first three already hold
    assert (report.n_rows, report.rank, report.n_redundant) == (38, 35, 3)
    assert report.redundant == ("joints.D[2]", "joints.D[3]", "joints.D[4]")
    assert {"joints.A", "joints.B", "joints.C", "joints.D"} <= set(report.parts)
    assert bilateral_redundancy(*four_bar(2).build()[:2]) is None


@pytest.fixture(scope="module")
def spatial_four_bar():
    return run(four_bar(3), 0.3)[1]


def test_a_four_bar_built_in_3d_keeps_its_plane_and_its_crank_rocker_relation(spatial_four_bar):
    q = np.asarray(spatial_four_bar.q)
    assert max_violation(spatial_four_bar) < 1e-9
    for k in range(3):  # crank, coupler, rocker: no out-of-plane position, their z axes are the world's
        np.testing.assert_allclose(q[:, 12 * k + np.array([2, 5, 8, 9, 10])], 0.0, atol=1e-12)
        np.testing.assert_allclose(q[:, 12 * k + 11], 1.0, atol=1e-12)
    # the closed loop's relation, on a crank that gravity turned by half a radian (6.9 rad/s at the end)
    crank, rocker = np.arctan2(q[:, 4], q[:, 3]), np.arctan2(q[:, 28], q[:, 27])
    np.testing.assert_allclose(rocker, [rocker_angle(c) for c in crank], atol=1e-9)
    assert np.ptp(crank) > 0.5


@pytest.mark.slow  # a second run (some 30 s on two cores)
def test_a_four_bar_built_in_3d_moves_as_the_planar_one(spatial_four_bar):
    q3, q2 = np.asarray(spatial_four_bar.q), np.asarray(run(four_bar(2), 0.3)[1].q)
    # natural coordinates and an angle are discretised apart: with the crank at 6.9 rad/s at the end the two agree
    # to 1.5e-7 m and 1.1e-6 rad at h = 1e-3 s, and a hundred times closer at h = 5e-4 s (checked once: each run
    # compiles for tens of seconds)
    for k in range(3):  # crank, coupler, rocker: centre of mass and angle
        body3, body2 = q3[:, 12 * k:12 * (k + 1)], q2[:, 3 * k:3 * (k + 1)]
        np.testing.assert_allclose(body3[:, :2], body2[:, :2], atol=1e-6)
        np.testing.assert_allclose(np.arctan2(body3[:, 4], body3[:, 3]), body2[:, 2], atol=5e-6)
