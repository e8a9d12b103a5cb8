"""Block elimination of the bordered iteration matrices of systems of bodies
(nsga_jax/_integrators/structured.py, block_tridiagonal.py): the block
elimination against dense solves, the layouts a chain, a shuffled chain, a
ring and a star get, the bordered correction against the Schur complement
of linalg.solve_bordered, and whole runs against the dense path
(``fast_paths=False``): every scheme, a closed ring, float32, batches, both
adjoints, impacts at their instants and a 3D chain of hinged links."""

import contextlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import nsga_jax as nj
from nsga_jax import _batch as batch
from nsga_jax._integrators import structured
from nsga_jax._integrators.block_tridiagonal import dense_of, gauss_jordan, solve_block_tridiagonal
from nsga_jax._integrators.linalg import Factorisation, solve_bordered
from nsga_jax._integrators.structured import MIN_BLOCKS, Structured, StructuredFactorisation, block_layout
from nsga_jax._models.coupling import BodyCoupling
from nsga_jax.system import Pin, PlaneContact, Revolute, RigidBody2D, RigidBody3D, System

LENGTH, MASS = 0.2, 0.5
SMALL = 6
"""The block elimination is used from MIN_BLOCKS (20) blocks, where it is
faster; these tests lower the threshold to SMALL blocks, so that chains of
8 to 12 links check it at a tenth of the cost."""


def clear_programs():
    structured.block_layout.cache_clear()
    batch._EXECUTABLES.clear()
    jax.clear_caches()


@pytest.fixture(autouse=True, scope="module")
def small_threshold():
    saved = structured.MIN_BLOCKS
    structured.MIN_BLOCKS = SMALL
    clear_programs()
    yield
    structured.MIN_BLOCKS = saved
    clear_programs()


def chain(n_links: int, order=None, ring: bool = False, floor: float | None = None):
    """A chain of n_links rigid rods pinned in series to the ground (bodies
    added in ``order``), its tip against a wall (``floor``: against a floor
    that high [m] instead, which the falling tip reaches in a tenth of a
    second); ``ring``: the rods on a regular polygon, the last pinned back to
    the first (a closed loop, its first vertex pinned to the ground)."""
    system = System(dim=2, gravity=[0.0, -9.81])
    order = list(range(n_links)) if order is None else order
    radius = LENGTH / (2 * np.sin(np.pi / n_links))
    for i in order:
        if ring:  # rod i from vertex i to vertex i + 1, at angle 2πi/n + π/2 + π/n
            a, b = (radius * np.array([np.cos(2 * np.pi * k / n_links), np.sin(2 * np.pi * k / n_links)])
                    for k in (i, i + 1))
            body = RigidBody2D(MASS, MASS * LENGTH**2 / 12, (a + b) / 2, angle=np.arctan2(*(b - a)[::-1]))
        else:
            body = RigidBody2D(MASS, MASS * LENGTH**2 / 12, [(i + 0.5) * LENGTH, 0.0])
        system.add_body(f"link{i}", body)
    for i in range(n_links):
        parent = "ground" if i == 0 else f"link{i - 1}"
        at_parent = ([radius, 0.0] if ring else [0.0, 0.0]) if i == 0 else [LENGTH / 2, 0.0]
        system.add_joint(f"pin{i}", Pin(parent, f"link{i}", at_a=at_parent, at_b=[-LENGTH / 2, 0.0]))
    if ring:
        system.add_joint("close", Pin(f"link{n_links - 1}", "link0", at_a=[LENGTH / 2, 0.0], at_b=[-LENGTH / 2, 0.0]))
    else:
        normal, origin = ([1.0, 0.0], [-0.6 * n_links * LENGTH, 0.0]) if floor is None else ([0.0, 1.0], [0.0, floor])
        system.add_contact("wall", PlaneContact(f"link{n_links - 1}", normal=normal, origin=origin, e=0.5,
                                                points=[[LENGTH / 2, 0.0]]))
    return system.build()[0]


def random_blocks(p, s, seed):
    rng = np.random.default_rng(seed)
    diag = rng.standard_normal((p, s, s)) + 3 * s * np.eye(s)
    lower, upper = rng.standard_normal((2, max(p - 1, 0), s, s))
    return tuple(jnp.asarray(x) for x in (diag, lower, upper, rng.standard_normal((p, s))))


# ----------------------------------------------------------- block elimination
@pytest.mark.parametrize("p", [1, 2, 3, 7, 50])
def test_block_elimination_solves_the_block_tridiagonal_system(p):
    diag, lower, upper, rhs = random_blocks(p, 4, p)
    x = jax.jit(solve_block_tridiagonal)(diag, lower, upper, rhs)
    dense = dense_of(diag, lower, upper)
    np.testing.assert_allclose(dense @ x.ravel(), rhs.ravel(), atol=1e-13)
    np.testing.assert_allclose(x.ravel(), np.linalg.solve(dense, rhs.ravel()), rtol=1e-12, atol=1e-13)


def test_gauss_jordan_equals_lapack_and_batches():
    blocks = random_blocks(6, 5, 0)
    diag, right = blocks[0], jnp.concatenate([blocks[1][:5], blocks[3][:5, :, None]], axis=2)  # (5, 5, 6)
    want = np.linalg.solve(diag[:5], right)
    augmented = jnp.concatenate([diag[:5], right], axis=2)
    np.testing.assert_allclose(jax.vmap(gauss_jordan)(augmented), want, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(gauss_jordan(augmented[2]), want[2], rtol=1e-12, atol=1e-14)


def test_block_elimination_gradient_equals_the_dense_solves():
    diag, lower, upper, rhs = random_blocks(9, 3, 1)

    def loss(solve, d, lo, up, b):
        return jnp.sum(jnp.sin(solve(d, lo, up, b)))

    def dense(d, lo, up, b):
        return jnp.linalg.solve(dense_of(d, lo, up), b.ravel())

    got = jax.grad(loss, argnums=(1, 2, 3, 4))(solve_block_tridiagonal, diag, lower, upper, rhs)
    want = jax.grad(loss, argnums=(1, 2, 3, 4))(dense, diag, lower, upper, rhs)
    for g, w in zip(got, want):
        np.testing.assert_allclose(g, w, rtol=1e-10, atol=1e-12)


def test_block_elimination_batches():
    members = [random_blocks(6, 3, seed) for seed in range(3)]
    stacked = [jnp.stack(x) for x in zip(*members)]
    x = jax.vmap(solve_block_tridiagonal)(*stacked)
    for i, blocks in enumerate(members):
        np.testing.assert_allclose(x[i], solve_block_tridiagonal(*blocks), rtol=1e-13, atol=1e-14)


# --------------------------------------------------------------------- layouts
def test_a_chain_is_one_body_per_block_with_its_pin():
    model = chain(12)
    layout = block_layout(model.body_coupling, model.n_constraints)
    assert layout is not None and layout.blocks == 12
    n = model.n_dof
    for i in range(11):  # link i's three coordinates and its pin's two rows
        assert sorted(layout.unknowns[i][layout.unknowns[i] >= 0]) == [3 * i, 3 * i + 1, 3 * i + 2,
                                                                  n + 2 * i, n + 2 * i + 1]
    assert n + model.n_constraints - 1 in layout.unknowns[-1]  # the wall's row, with the last link


def test_a_shuffled_chain_is_reordered_along_its_pins():
    order = list(np.random.default_rng(3).permutation(12))
    model = chain(12, order=order)
    layout = block_layout(model.body_coupling, model.n_constraints)
    assert layout is not None and layout.blocks == 12  # reverse Cuthill-McKee: one link per block again


def test_a_ring_gets_two_bodies_per_block_and_a_star_stays_dense():
    model = chain(12, ring=True)
    layout = block_layout(model.body_coupling, model.n_constraints)
    assert layout is not None and layout.blocks == 6
    star = BodyCoupling(dofs=tuple((3 * i, 3 * i + 3) for i in range(12)),
                        rows=tuple((0, i) for i in range(1, 12)), pairs=())
    assert block_layout(star, 11) is None  # every body couples with the hub: one block
    assert block_layout(chain(SMALL - 1).body_coupling, 0) is None
    heavy = BodyCoupling(dofs=((0, 60),) + tuple((60 + 3 * i, 63 + 3 * i) for i in range(11)),
                         rows=tuple((i, i + 1) for i in range(11)), pairs=())
    assert block_layout(heavy, 11) is None  # a block of 60 coordinates and more: dense
    assert block_layout(heavy._replace(dofs=tuple((3 * i, 3 * i + 3) for i in range(12))), 11) is not None


def test_structure_is_chosen_at_trace_time(monkeypatch):
    monkeypatch.setattr(structured, "MIN_BLOCKS", MIN_BLOCKS)  # the default
    structured.block_layout.cache_clear()
    kinds = nj.DS().matrix_kinds(chain(MIN_BLOCKS))
    assert kinds == (Structured, Structured, Structured)
    assert Structured not in nj.DS().matrix_kinds(chain(MIN_BLOCKS - 1))
    assert Structured not in nj.DS(fast_paths=False).matrix_kinds(chain(MIN_BLOCKS))
    structured.block_layout.cache_clear()


def test_check_model_checks_a_declared_coupling():
    model = chain(8)
    assert "body_coupling" in nj.check_model(model)
    wrong = model.body_coupling._replace(rows=((0,),) * model.n_constraints)

    class Lying(type(model)):
        @property
        def body_coupling(self):
            return wrong

    liar = Lying(model.bodies, model.joints, model.contacts, model.forces, model.body_names, model.joint_names,
                 model.contact_names, model.force_names, model.dim)
    with pytest.raises(nj.ConfigError, match="body_coupling"):
        nj.check_model(liar)


# ------------------------------------------------------- the bordered correction
@pytest.mark.parametrize("rows", ["bilateral", "all", "some active", "smooth"])
def test_bordered_correction_equals_the_schur_complement(rows):
    model = chain(10)
    rng = np.random.default_rng(5)
    q = model.initial_state()[0] + 0.3 * jnp.asarray(rng.standard_normal(model.n_dof))
    m = model.n_bilateral if rows in ("bilateral", "smooth") else model.n_constraints
    n = model.n_dof
    A = model.mass(q) + 1e-5 * jnp.asarray(model.body_coupling.allowed_matrix(m) * rng.standard_normal((n, n)))
    G = model.constraint_jacobian(q)[:m]
    G_low = G + 0.01 * jnp.asarray(model.body_coupling.allowed_rows()[:m] * rng.standard_normal((m, n))) \
        if rows == "smooth" else G
    active = jnp.asarray(rng.random(m) < 0.5) if rows == "some active" else jnp.ones((m,), bool)
    r1, r2 = jnp.asarray(rng.standard_normal(n)), jnp.asarray(rng.standard_normal(m))
    want = solve_bordered(Factorisation.of(A, 0.0, 0.0), r1, r2, G, G_low, active, 2.0, 3.0)
    got = StructuredFactorisation(matrix=A, K_norm=0.0, C_norm=0.0, coupling=model.body_coupling).bordered(
        r1, r2, G, G_low, active, 2.0, 3.0)
    for g, w in zip(got, want):
        np.testing.assert_allclose(g, w, rtol=1e-9, atol=1e-9 * float(jnp.abs(w).max()))
    plain = StructuredFactorisation(matrix=A, K_norm=0.0, C_norm=0.0, coupling=model.body_coupling)
    np.testing.assert_allclose(plain.solve(r1), np.linalg.solve(A, r1), rtol=1e-10)


# ---------------------------------------------------------------- whole runs
H = 1e-3
FLOOR = -0.02  # the falling tip of an 8-link chain reaches it at t = 0.06 s


@pytest.mark.parametrize("scheme", ["DS", *(pytest.param(s, marks=pytest.mark.slow) for s in ("DSn", "CS", "MJ"))])
def test_a_chain_runs_as_on_the_dense_path(scheme):
    model = chain(8, floor=FLOOR)
    q0, v0 = model.initial_state()
    fast = getattr(nj, scheme)()
    assert Structured in fast.matrix_kinds(model)
    # Moreau-Jean holds the contact at velocity level: the tip penetrates the floor, and the run says so
    with pytest.warns(nj.InvariantWarning, match="penetration") if scheme == "MJ" else contextlib.nullcontext():
        runs = [nj.simulate(model, s, 0.0, 0.1, H, q0, v0) for s in (fast, getattr(nj, scheme)(fast_paths=False))]
    for sol in runs:
        assert sol.stats["result"] == "successful"
    np.testing.assert_allclose(runs[0].q, runs[1].q, atol=1e-10)
    np.testing.assert_allclose(runs[0].v, runs[1].v, atol=1e-8)
    tip_height = np.asarray(jax.vmap(model.unilateral)(jnp.asarray(runs[0].q)))[:, 0]
    # it reached the floor and bounced: its contact row was active
    assert abs(tip_height.min()) < (1e-3 if scheme == "MJ" else 1e-6) and tip_height[-1] > 1e-3


@pytest.mark.slow
def test_a_closed_ring_holds_its_pins():
    model = chain(12, ring=True)
    assert nj.DS().matrix_kinds(model)[0] is Structured
    q0, v0 = model.initial_state()
    runs = [nj.simulate(model, s, 0.0, 0.2, H, q0, v0) for s in (nj.DS(), nj.DS(fast_paths=False))]
    for sol in runs:
        assert sol.stats["result"] == "successful"
        assert np.abs(np.asarray(jax.vmap(model.bilateral)(jnp.asarray(sol.q)))).max() < 1e-9
    np.testing.assert_allclose(runs[0].q, runs[1].q, atol=1e-10)


@pytest.mark.slow
def test_float32_and_batches_run_as_on_the_dense_path():
    model = chain(8, floor=FLOOR)
    q0, v0 = model.initial_state()
    single = [nj.simulate(model, s, 0.0, 0.1, H, q0, v0, dtype="float32") for s in (nj.DS(), nj.DS(fast_paths=False))]
    assert all(s.stats["result"] == "successful" for s in single)
    np.testing.assert_allclose(single[0].q, single[1].q, atol=2e-4)
    hs = [1e-3, 2e-3]
    batches = [nj.simulate_batch(model, s, 0.0, 0.1, hs, q0, v0) for s in (nj.DS(), nj.DS(fast_paths=False))]
    for a, b in zip(*batches):
        np.testing.assert_allclose(a.q, b.q, atol=1e-10)


@pytest.mark.parametrize("adjoint", [nj.DiscreteAdjoint(),
                                     pytest.param(nj.ImpactTimeAdjoint(), marks=pytest.mark.slow)],
                         ids=["discrete", "impact-time"])
def test_adjoints_equal_the_dense_paths(adjoint):
    model = chain(8, floor=FLOOR)
    q0, v0 = model.initial_state()
    steps = 80  # through the tip's impact on the floor

    def loss(scheme, spin):
        sol = nj.integrate(model, scheme, 0.0, steps * H, H, q0, v0.at[-1].set(spin), n_steps=steps, adjoint=adjoint)
        return jnp.sum(sol.q[-1] ** 2)

    got = jax.value_and_grad(lambda x: loss(nj.DS(), x))(-3.0)
    want = jax.value_and_grad(lambda x: loss(nj.DS(fast_paths=False), x))(-3.0)
    assert abs(float(got[1])) > 1e-6
    np.testing.assert_allclose(got, want, rtol=1e-8)


# ------------------------------------------------- with the other features
@pytest.mark.slow
def test_impacts_at_their_instants_run_as_on_the_dense_path():
    model = chain(8, floor=FLOOR)
    q0, v0 = model.initial_state()
    runs = [nj.simulate(model, nj.DS(impact_instants=True, fast_paths=fast), 0.0, 0.1, H, q0, v0)
            for fast in (True, False)]
    assert Structured in nj.DS(impact_instants=True).matrix_kinds(model)
    for sol in runs:
        assert sol.stats["result"] == "successful"
        assert sol.stats["impacts_at_instants"] >= 1 and sol.stats["instant_fallbacks"] == 0
    np.testing.assert_allclose(runs[0].q, runs[1].q, atol=1e-10)
    np.testing.assert_allclose(runs[0].v, runs[1].v, atol=1e-8)


@pytest.mark.slow
def test_a_3d_chain_of_hinged_links_runs_as_on_the_dense_path():
    """Eight RigidBody3D links on Revolute hinges (blocks of 7 coordinates, a
    unit-quaternion row and five hinge rows each), the tip above a floor.
    Tight Newton tolerances: at the default ones the two paths may stop a
    Newton loop one iteration apart, which moves the runs by ~1e-6."""
    links = 8
    system = System(dim=3, gravity=[0.0, -9.81, 0.0])
    inertia = [1e-5, MASS * LENGTH**2 / 12, MASS * LENGTH**2 / 12]
    for i in range(links):
        system.add_body(f"link{i}", RigidBody3D(MASS, inertia, position=[(i + 0.5) * LENGTH, 0.0, 0.0]))
        system.add_joint(f"hinge{i}", Revolute("ground" if i == 0 else f"link{i - 1}", f"link{i}",
                                               axis=[0.0, 0.0, 1.0], at_a=[0.0 if i == 0 else LENGTH / 2, 0.0, 0.0],
                                               at_b=[-LENGTH / 2, 0.0, 0.0]))
    system.add_contact("floor", PlaneContact(f"link{links - 1}", normal=[0.0, 1.0, 0.0], origin=[0.0, FLOOR, 0.0],
                                             e=0.5, points=[[LENGTH / 2, 0.0, 0.0]]))
    model = system.build()[0]
    q0, v0 = model.initial_state()
    tight = dict(tol_r=1e-10, tol_f=1e-10)
    assert nj.DS().matrix_kinds(model)[0] is Structured
    runs = [nj.simulate(model, nj.DS(**tight, fast_paths=fast), 0.0, 0.1, H, q0, v0) for fast in (True, False)]
    for sol in runs:
        assert sol.stats["result"] == "successful"
        assert sol.stats["max_bilateral_violation_position"] < 1e-9
    np.testing.assert_allclose(runs[0].q, runs[1].q, atol=1e-9)
    tip_height = np.asarray(jax.vmap(model.unilateral)(jnp.asarray(runs[0].q)))[:, 0]
    # it fell onto the floor (0.02 m below the tip) and hit it: its contact row was active
    assert abs(tip_height.min()) < 1e-6 and np.asarray(runs[0].records.active_velocity).any()
