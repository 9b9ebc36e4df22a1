"""Reference staggered assembly: thesis stencil, symmetry, rigid modes, energy, affine patch test, mass."""

import itertools

import numpy as np
import pytest

from engine.errors import GridError
from engine.geometry.fractions import volume_fractions
from engine.grid import Grid
from engine.staggered.assembly import (
    active_dofs,
    box_fractions,
    dof_components,
    dof_count,
    dof_index,
    dof_positions,
    index_box,
    mass,
    rigid_modes,
    stiffness,
    strain_operators,
    supported_edges,
)
from tests.conftest import polygon_surface_2d

LAM, MU, H = 1.7, 0.6, 0.25


def pairs(d):
    return list(itertools.combinations(range(d), 2))


def clip_to_grid(cell, edges):
    """Zero the weights whose stencil would leave the index box (cells on the high layer, edges on the low faces)."""
    cell = cell.copy()
    for k in range(cell.ndim):
        np.moveaxis(cell, k, 0)[-1] = 0
    edges = {p: v.copy() for p, v in edges.items()}
    for (a, b), v in edges.items():
        np.moveaxis(v, a, 0)[0] = 0
        np.moveaxis(v, b, 0)[0] = 0
    return cell, edges


def full(shape):
    box = tuple(n + 1 for n in shape)
    return clip_to_grid(np.ones(box), {p: np.ones(box) for p in pairs(len(shape))})


def random_fractions(shape, rng, zeros=0.2):
    box = tuple(n + 1 for n in shape)

    def draw():
        v = rng.uniform(0, 1, box)
        v[rng.uniform(size=box) < zeros] = 0
        return v

    return clip_to_grid(draw(), {p: draw() for p in pairs(len(shape))})


def grid_of(shape):
    return Grid(origin=tuple(0.3 - 0.1 * k for k in range(len(shape))), spacing=H, shape=shape)


def stencil_row(shape, a, index, normal, tangential, cross):
    """Row of the constant-coefficient staggered operator L_h (units 1/h^2) for DOF (a, I), as a dense vector.

    L_h u_a = normal d_aa u_a + tangential sum_{b != a} d_bb u_a + cross sum_{b != a} d_ab u_b, with the
    second differences d_bb and the staggered mixed difference
    d_ab u_b(I) = [u_b(I + e_b) - u_b(I) - u_b(I - e_a + e_b) + u_b(I - e_a)] / h^2.
    """
    d = len(shape)
    e = np.eye(d, dtype=int)
    row = np.zeros(dof_count(shape))
    index = np.asarray(index)

    def add(comp, at, coef):
        row[dof_index(comp, at, shape)] += coef / H**2

    for b in range(d):
        coef = normal if b == a else tangential
        add(a, index, -2 * coef)
        add(a, index + e[b], coef)
        add(a, index - e[b], coef)
        if b != a:
            add(b, index + e[b], cross)
            add(b, index, -cross)
            add(b, index - e[a] + e[b], -cross)
            add(b, index - e[a], cross)
    return row


def interior(shape, margin=2):
    return itertools.product(*(range(margin, n - margin + 1) for n in shape))


def test_dof_layout():
    shape = (3, 4)
    g = grid_of(shape)
    assert dof_count(shape) == 2 * 4 * 5 == 40 and dof_count((2, 3, 4)) == 3 * 3 * 4 * 5
    assert dof_index(1, np.array([2, 3]), shape) == 20 + 2 * 5 + 3
    np.testing.assert_array_equal(dof_components(shape), [0] * 20 + [1] * 20)
    pos = dof_positions(g)
    assert pos.shape == (40, 2)
    # u_x(2, 3) on the low x-face of cell (2, 3): x = 0.3 + 0.25 * 2, y = 0.2 + 0.25 * 3.5
    np.testing.assert_allclose(pos[dof_index(0, np.array([2, 3]), shape)], [0.8, 1.075], rtol=1e-15)
    np.testing.assert_allclose(pos[dof_index(1, np.array([2, 3]), shape)], [0.925, 0.95], rtol=1e-15)
    with pytest.raises(ValueError):
        dof_index(0, np.array([4, 0]), shape)


def test_2d_full_rows_are_the_thesis_stencil_with_lambda_plus_mu_cross_term():
    """Interior rows of K equal -h^2 times thesis eq. 3.14/3.15 -- with the cross coefficient (lambda + mu)/h^2.

    The thesis prints mu/h^2 in front of y_{i+1,j+1} - y_{i+1,j-1} - y_{i-1,j+1} + y_{i-1,j-1}; its
    own energy (eq. 4.8) and the PDE L = mu Lap + (mu + lambda) grad div give lambda + mu, so 3.14 has a
    typo. Its cross-term indices count half cells: y_{i+1,j+1} is the y-DOF h/2 right and h/2 above x_{i,j}.
    Eq. 3.15 is the mirror image of 3.14 (2 mu + lambda along y for the y-DOFs); read literally with i
    along x it would put 2 mu + lambda along x, the same kind of slip, so the y rows are checked against
    the mirrored 3.14.
    """
    shape = (8, 8)
    k = stiffness(*full(shape), H, LAM, MU).toarray()
    rows = 0
    for i, j in interior(shape):
        I = np.array([i, j])
        # x_{i,j} = u_0(I) at (i, j + 1/2) h; its diagonal neighbours y_{i+-1, j+-1} (half-cell steps):
        y_pp, y_pm = dof_index(1, I + [0, 1], shape), dof_index(1, I, shape)
        y_mp, y_mm = dof_index(1, I + [-1, 1], shape), dof_index(1, I + [-1, 0], shape)
        thesis = np.zeros(dof_count(shape))
        thesis[dof_index(0, I, shape)] = -(6 * MU + 2 * LAM)
        for nb in ([1, 0], [-1, 0]):
            thesis[dof_index(0, I + nb, shape)] = 2 * MU + LAM
        for nb in ([0, 1], [0, -1]):
            thesis[dof_index(0, I + nb, shape)] = MU
        cross = np.zeros_like(thesis)
        cross[[y_pp, y_pm, y_mp, y_mm]] = [1, -1, -1, 1]
        row = k[dof_index(0, I, shape)]
        np.testing.assert_allclose(row, -H**2 * (thesis + (LAM + MU) * cross) / H**2, rtol=0, atol=1e-14)
        printed = -H**2 * (thesis + MU * cross) / H**2
        np.testing.assert_allclose(row - printed, -LAM * cross, rtol=0, atol=1e-14)  # printed mu/h^2 is off by lambda
        # y rows: the mirror image of 3.14
        y_row = k[dof_index(1, I, shape)]
        np.testing.assert_allclose(y_row, -H**2 * stencil_row(shape, 1, I, 2 * MU + LAM, MU, LAM + MU), atol=1e-14)
        literal = -H**2 * stencil_row(shape, 1, I, MU, 2 * MU + LAM, LAM + MU)
        assert np.abs(y_row - literal).max() == pytest.approx(MU + LAM, rel=1e-12)
        rows += 2
    assert rows == 2 * 5 * 5


def test_3d_full_rows_are_the_standard_staggered_stencil():
    shape = (6, 5, 6)
    k = stiffness(*full(shape), H, LAM, MU)
    for I in interior(shape):
        for a in range(3):
            row = k[dof_index(a, np.array(I), shape)].toarray().ravel()
            expect = -H**3 * stencil_row(shape, a, I, 2 * MU + LAM, MU, LAM + MU)
            np.testing.assert_allclose(row, expect, rtol=0, atol=1e-15)
            assert np.count_nonzero(row) == 1 + 6 + 2 * 4  # centre, 6 neighbours, 2 x 4 cross entries


@pytest.mark.parametrize("shape", [(7, 6), (4, 5, 4)])
def test_symmetric_and_rigid_modes_in_kernel(shape, rng):
    cell, edges = random_fractions(shape, rng)
    k = stiffness(cell, edges, H, LAM, MU)
    scale = abs(k).max()
    assert abs(k - k.T).max() <= 1e-15 * scale
    modes = rigid_modes(dof_positions(grid_of(shape)), dof_components(shape))
    d = len(shape)
    assert modes.shape == (dof_count(shape), d + d * (d - 1) // 2)
    assert np.abs(k @ modes).max() <= 1e-13 * scale * np.abs(modes).max()


def blob(shape, radius, rng):
    """Connected ball of cells with random fractions, some tiny (1e-5 .. 1e-2), and random edge weights
    wherever any of the four cells around the edge is solid (as exact fractions of a shape give them).

    Raw, those edge weights create mechanisms: faces held by shear alone next to convex corners.
    ``supported_edges`` removes them; see test_corner_nodes_are_dropped_with_their_mechanisms.
    """
    d = len(shape)
    box = tuple(n + 1 for n in shape)
    centres = np.indices(box).astype(float) + 0.5
    mid = np.array(shape, dtype=float)[(slice(None),) + (None,) * d] / 2
    inside = np.sum((centres - mid) ** 2, axis=0) <= radius**2

    def draw():
        v = rng.uniform(0.05, 1.0, box)
        tiny = rng.uniform(size=box) < 0.15
        v[tiny] = 10.0 ** rng.uniform(-5, -2, tiny.sum())
        return v

    cell = np.where(inside, draw(), 0.0)
    edges = {}
    for a, b in pairs(d):
        # the four cells I, I - e_a, I - e_b, I - e_a - e_b around edge (a, b) at I
        around = [np.roll(inside, (sa, sb), axis=(a, b)) for sa, sb in itertools.product((0, 1), repeat=2)]
        edges[(a, b)] = np.where(np.logical_or.reduce(around), draw(), 0.0)
    return clip_to_grid(cell, edges)


@pytest.mark.parametrize("shape", [(6, 5), (4, 5, 3)])
def test_active_dofs_and_supported_edges_by_their_definitions(shape, rng):
    cell, edges = random_fractions(shape, rng, zeros=0.6)
    d, box = len(shape), cell.shape
    e = np.eye(d, dtype=int)
    act = active_dofs(cell)

    def is_active(a, I):
        return all(0 <= i < n for i, n in zip(I, box)) and act[dof_index(a, np.array(I), shape)]

    for I in itertools.product(*(range(n) for n in box)):
        I = np.array(I)
        for a in range(d):
            lower = I - e[a]
            want = cell[tuple(I)] > 0 or (I[a] > 0 and cell[tuple(lower)] > 0)
            assert is_active(a, I) == want
    kept = supported_edges(cell, edges)
    dropped = 0
    for (a, b), v in edges.items():
        for I in itertools.product(*(range(n) for n in box)):
            I = np.array(I)
            four = is_active(a, I) and is_active(a, I - e[b]) and is_active(b, I) and is_active(b, I - e[a])
            assert kept[(a, b)][tuple(I)] == (v[tuple(I)] if four else 0.0)
            dropped += bool(v[tuple(I)] and not four)
    assert dropped > 0


@pytest.mark.parametrize("shape,radius", [((12, 12), 4.5), ((7, 7, 7), 2.6)])
def test_supported_edges_leave_exactly_the_rigid_modes(shape, radius, rng):
    d = len(shape)
    rigid = d + d * (d - 1) // 2
    cell, raw = blob(shape, radius, rng)
    act = active_dofs(cell)
    assert act.sum() > 100
    np.testing.assert_array_equal(active_dofs(cell, raw), act)  # edges do not make DOFs active

    # raw edge weights: DOFs held by shear alone add zero-energy mechanisms beyond the rigid modes
    k_raw = stiffness(cell, raw, H, LAM, MU).toarray()
    held = np.abs(k_raw).sum(axis=1) > 0
    ev_raw = np.linalg.eigvalsh(k_raw[np.ix_(held, held)])
    assert held.sum() > act.sum() and np.sum(ev_raw < 1e-12 * ev_raw[-1]) > rigid

    edges = supported_edges(cell, raw)
    k = stiffness(cell, edges, H, LAM, MU).toarray()
    # K touches no inactive DOF, and the kept weights are the raw ones
    assert not np.any(k[~act]) and not np.any(k[:, ~act])
    for p, v in edges.items():
        assert np.all((v == raw[p]) | (v == 0)) and 0 < np.count_nonzero(v) < np.count_nonzero(raw[p])
    ev = np.linalg.eigvalsh(k[np.ix_(act, act)])
    # exactly the rigid motions are free (d translations, d(d-1)/2 rotations): no mechanisms, even
    # with fractions down to 1e-5 (the smallest non-zero eigenvalue scales with them, not with round-off)
    assert np.sum(ev < 1e-12 * ev[-1]) == rigid
    assert ev[rigid - 1] < 1e-14 * ev[-1] and ev[rigid] > 1e-9 * ev[-1]
    modes = rigid_modes(dof_positions(grid_of(shape)), dof_components(shape))[act]
    assert np.linalg.matrix_rank(modes) == rigid
    assert np.abs(k[np.ix_(act, act)] @ modes).max() <= 1e-13 * ev[-1] * np.abs(modes).max()

    # pin the 2d face DOFs of three cells in an L (a single cell would leave the rotation about it free)
    pinned = np.zeros_like(act)
    e = np.eye(d, dtype=int)
    centre = np.array(shape) // 2
    for c in (centre, centre + 2 * e[0], centre + 2 * e[1]):
        for a in range(d):
            pinned[dof_index(a, np.stack([c, c + e[a]]), shape)] = True
    assert np.all(act[pinned])
    keep = act & ~pinned
    ev = np.linalg.eigvalsh(k[np.ix_(keep, keep)])
    assert ev[0] > 1e-10 * ev[-1]


@pytest.mark.parametrize("shape,radius", [((12, 12), 4.5), ((7, 7, 7), 2.6)])
def test_dropped_edge_terms_only_remove_stiffness(shape, radius, rng):
    """Minimising the raw energy over the DOFs that only edges hold gives K(supported_edges) plus a
    PSD rest: exactly zero in 2D (each dropped node's shear is cancelled by its edge-only DOFs). In 3D
    an edge-only DOF meets up to four shear terms and cannot cancel them all, so the rest is not zero
    (about 0.1 of max |K| for this blob): dropping those terms lowers the energy there."""
    cell, raw = blob(shape, radius, rng)
    act = active_dofs(cell)
    k_raw = stiffness(cell, raw, H, LAM, MU).toarray()
    only_edges = (np.abs(k_raw).sum(axis=1) > 0) & ~act
    kaa, kae, kee = k_raw[np.ix_(act, act)], k_raw[np.ix_(act, only_edges)], k_raw[np.ix_(only_edges, only_edges)]
    schur = kaa - kae @ np.linalg.pinv(kee, rcond=1e-13, hermitian=True) @ kae.T
    rest = np.linalg.eigvalsh(schur - stiffness(cell, supported_edges(cell, raw), H, LAM, MU).toarray()[np.ix_(act, act)])
    scale = np.abs(kaa).max()
    assert rest[0] > -1e-12 * scale
    if len(shape) == 2:
        assert rest[-1] < 1e-12 * scale


def direct_energy(u, cell, edges, h, lam, mu):
    """The discrete energy of common.md summed sample by sample."""
    d = cell.ndim
    box = cell.shape
    U = u.reshape((d,) + box)
    e = np.eye(d, dtype=int)
    energy = 0.0
    for I in itertools.product(*(range(n) for n in box)):
        I = np.array(I)
        if cell[tuple(I)] != 0:
            eps = [(U[(a, *(I + e[a]))] - U[(a, *I)]) / h for a in range(d)]
            energy += h**d * cell[tuple(I)] * (mu * sum(x * x for x in eps) + lam / 2 * sum(eps) ** 2)
        for a, b in pairs(d):
            if edges[(a, b)][tuple(I)] != 0:
                eps_ab = 0.5 * ((U[(a, *I)] - U[(a, *(I - e[b]))]) / h + (U[(b, *I)] - U[(b, *(I - e[a]))]) / h)
                energy += h**d * edges[(a, b)][tuple(I)] * 2 * mu * eps_ab**2
    return energy


@pytest.mark.parametrize("shape", [(4, 5), (3, 3, 4)])
def test_quadratic_form_is_the_discrete_energy(shape, rng):
    cell, edges = random_fractions(shape, rng)
    k = stiffness(cell, edges, H, LAM, MU)
    for _ in range(3):
        u = rng.normal(size=dof_count(shape))
        assert 0.5 * u @ (k @ u) == pytest.approx(direct_energy(u, cell, edges, H, LAM, MU), rel=1e-12)


@pytest.mark.parametrize("shape", [(9, 8), (6, 7, 6)])
def test_affine_displacement_gives_boundary_jumps_of_constant_stress(shape, rng):
    """u = G x + c: constant strain sym(G), constant stress; K u is the jump of the weights times that stress."""
    d = len(shape)
    cell, edges = random_fractions(shape, rng)
    core = tuple(slice(2, n - 2) for n in shape)  # a full block, so some rows see no jump at all
    cell[core] = 1
    for v in edges.values():
        v[core] = 1
    g, c = rng.normal(size=(d, d)), rng.normal(size=d)
    pos, comp = dof_positions(grid_of(shape)), dof_components(shape)
    u = (pos @ g.T + c)[np.arange(len(comp)), comp]
    ku = stiffness(cell, edges, H, LAM, MU) @ u

    strain = 0.5 * (g + g.T)
    s = 2 * MU * strain + LAM * np.trace(strain) * np.eye(d)
    box = cell.shape
    expect = np.zeros((d,) + box)
    for a in range(d):
        for I in itertools.product(*(range(n) for n in box)):
            I = np.array(I)

            def w(v, at):
                return v[tuple(at)] if np.all(at >= 0) and np.all(at < box) else 0.0

            e = np.eye(d, dtype=int)
            jump = (w(cell, I - e[a]) - w(cell, I)) * s[a, a]
            for b in range(d):
                if b != a:
                    ve = edges[(min(a, b), max(a, b))]
                    jump += (w(ve, I) - w(ve, I + e[b])) * s[a, b]
            expect[(a, *I)] = H ** (d - 1) * jump
    expect = expect.ravel()
    scale = H ** (d - 1) * np.abs(s).max()
    np.testing.assert_allclose(ku, expect, rtol=0, atol=1e-12 * scale)
    quiet = np.abs(expect) == 0
    assert quiet.sum() > 20 and np.abs(ku[quiet]).max() <= 1e-12 * scale


def hand_square():
    """3 x 3 grid of unit cells, solid = cell (1, 1) exactly: the fractions by hand (index box 4 x 4)."""
    cell = np.zeros((4, 4))
    cell[1, 1] = 1.0
    faces = {0: np.zeros((4, 4)), 1: np.zeros((4, 4))}
    faces[0][[1, 2], 1] = 0.5  # x-faces at x = 1, 2 (boxes [x -+ 1/2] x [1, 2]) hold half the cell each
    faces[1][1, [1, 2]] = 0.5
    edges = {(0, 1): np.zeros((4, 4))}
    edges[(0, 1)][1:3, 1:3] = 0.25  # the four corner nodes hold a quarter cell each
    return cell, faces, edges


def test_active_dofs_and_mass_on_one_cell():
    cell, faces, edges = hand_square()
    shape = (3, 3)
    act = active_dofs(cell, edges)
    expect = np.zeros(dof_count(shape), dtype=bool)
    # exactly the cell's own faces: u_x(1, 1), u_x(2, 1), u_y(1, 1), u_y(1, 2)
    expect[dof_index(0, np.array([[1, 1], [2, 1]]), shape)] = True
    expect[dof_index(1, np.array([[1, 1], [1, 2]]), shape)] = True
    np.testing.assert_array_equal(act, expect)
    np.testing.assert_array_equal(active_dofs(cell), expect)
    # every corner node touches a face beside the cell, which no cell holds: all four are dropped
    assert np.count_nonzero(edges[(0, 1)]) == 4 and not np.any(supported_edges(cell, edges)[(0, 1)])
    k = stiffness(cell, supported_edges(cell, edges), 1.0, LAM, MU)
    np.testing.assert_array_equal(k.diagonal() > 0, act)

    m = mass(faces, 0.5, 1000.0)
    assert m[dof_index(0, np.array([1, 1]), shape)] == 1000.0 * 0.25 * 0.5
    assert m[dof_index(1, np.array([1, 2]), shape)] == 125.0
    assert np.count_nonzero(m) == 4 and m.sum() == 2 * 1000.0 * 0.25  # rho * volume per component
    np.testing.assert_array_equal(m > 0, act)  # here the unknowns are exactly the DOFs with mass


def test_corner_nodes_are_dropped_with_their_mechanisms():
    """The raw corner-node weights of one solid cell make 8 more DOFs (held by shear alone) and 3
    mechanisms on top of the 3 rigid motions; eliminating those 8 DOFs leaves exactly the stiffness of
    the cell term alone, which is K with ``supported_edges``: dropping the nodes loses no stiffness.
    On the 4 remaining DOFs only the 2 translations are free: the rotation vanishes there (each DOF
    lies on a centre line of the cell), so the single cell has no mechanism either."""
    cell, faces, edges = hand_square()
    k_raw = stiffness(cell, edges, 1.0, LAM, MU).toarray()
    held = np.abs(k_raw).sum(axis=1) > 0
    ev = np.linalg.eigvalsh(k_raw[np.ix_(held, held)])
    assert held.sum() == 12 and np.sum(ev < 1e-12 * ev[-1]) == 6
    act = active_dofs(cell)
    only_edge = held & ~act
    assert act.sum() == 4 and only_edge.sum() == 8
    kaa, kae, kee = k_raw[np.ix_(act, act)], k_raw[np.ix_(act, only_edge)], k_raw[np.ix_(only_edge, only_edge)]
    schur = kaa - kae @ np.linalg.pinv(kee) @ kae.T
    k = stiffness(cell, supported_edges(cell, edges), 1.0, LAM, MU).toarray()
    cell_only = stiffness(cell, {p: np.zeros_like(v) for p, v in edges.items()}, 1.0, LAM, MU).toarray()
    np.testing.assert_array_equal(k, cell_only)
    np.testing.assert_allclose(schur, k[np.ix_(act, act)], atol=1e-12)
    ev = np.linalg.eigvalsh(k[np.ix_(act, act)])
    assert np.sum(ev < 1e-12 * ev[-1]) == 2
    # K = B^T C B with C = 2 mu Id + lam 11^T on (eps_xx, eps_yy) and B B^T = 2 Id: eigenvalues 2 eig(C)
    np.testing.assert_allclose(ev[2:], [4 * MU, 2 * (2 * MU + 2 * LAM)], rtol=1e-12)


def test_box_fractions_of_a_real_square_match_the_hand_values():
    grid = Grid(origin=(0.0, 0.0), spacing=1.0, shape=(3, 3))
    square = polygon_surface_2d(np.array([[1.0, 1.0], [2.0, 1.0], [2.0, 2.0], [1.0, 2.0]]))
    cell, faces, edges = box_fractions(volume_fractions(square, grid))
    want_cell, want_faces, want_edges = hand_square()
    np.testing.assert_allclose(cell, want_cell, atol=1e-14)
    for a in range(2):
        np.testing.assert_allclose(faces[a], want_faces[a], atol=1e-14)
    np.testing.assert_allclose(edges[(0, 1)], want_edges[(0, 1)], atol=1e-14)


def test_strain_operators_and_input_errors(rng):
    shape = (3, 4, 2)
    b_cell, b_edge = strain_operators(shape, H)
    u = rng.normal(size=dof_count(shape))
    U = u.reshape((3, 4, 5, 3))
    eps = (b_cell @ u).reshape((3, 4, 5, 3))
    np.testing.assert_allclose(eps[1, 2, 3, 1], (U[1, 2, 4, 1] - U[1, 2, 3, 1]) / H, rtol=1e-14)
    assert eps[1, 2, 4, 1] == pytest.approx(-U[1, 2, 4, 1] / H, rel=1e-14)  # out-of-box neighbour dropped
    eps02 = (b_edge[(0, 2)] @ u).reshape((4, 5, 3))
    want = 0.5 * ((U[0, 1, 2, 2] - U[0, 1, 2, 1]) + (U[2, 1, 2, 2] - U[2, 0, 2, 2])) / H
    assert eps02[1, 2, 2] == pytest.approx(want, rel=1e-14)

    native = rng.uniform(size=(3, 4, 2))  # cells: extent n, padded on the high side
    padded = index_box(native, shape)
    assert padded.shape == (4, 5, 3) and np.all(padded[3] == 0) and np.all(padded[:3, :4, :2] == native)
    with pytest.raises(ValueError, match="fits neither"):
        index_box(np.ones((5, 5, 3)), shape)

    cell, edges = random_fractions(shape, rng)
    bad = cell.copy()
    bad[-1, 0, 0] = 0.5
    with pytest.raises(ValueError, match="outside the grid"):
        stiffness(bad, edges, H, LAM, MU)
    touching = {p: v.copy() for p, v in edges.items()}
    touching[(1, 2)][1, 0, 1] = 0.3
    with pytest.raises(GridError, match="padding"):
        stiffness(cell, touching, H, LAM, MU)
    with pytest.raises(ValueError, match="pairs"):
        stiffness(cell, {(0, 1): edges[(0, 1)]}, H, LAM, MU)
