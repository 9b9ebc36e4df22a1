"""End-to-end verification of the staggered method through ``engine.pipeline.run``.

Closed-form checks: a grid-aligned bar under uniaxial traction is reproduced exactly (affine
displacement, uniform stress); an affine displacement prescribed on a body's surface layer is
reproduced exactly inside (patch test, cut cells included); the Lame thick sphere under internal
pressure converges at second order; quasi-static ramps are linear; backward-Euler dynamics of a
1D bar has the period 4 L / c and relaxes to the static solution for large steps.
"""

import json
from pathlib import Path

import numpy as np
import pytest
import trimesh

from engine.geometry.cache import GeometryCache
from engine.material import lame_parameters
from engine.pipeline import Functions, run

ROOT = Path(__file__).resolve().parents[1]
SOLVER = {"rtol": 1e-12, "max_iterations": 5000, "precision": "f64", "arch": "cpu"}


def _spec(dim: int, geometry: dict, grid: dict, material: dict, boundaries: list, *, analysis=None,
          fields=("displacement",), probes=(), surface=False, rtol=1e-12, method=None) -> dict:
    return {
        "dimension": dim,
        "geometry": geometry,
        "grid": grid,
        "method": method or {"kind": "staggered"},
        "material": material,
        "boundaries": boundaries,
        "analysis": analysis or {"kind": "static"},
        "solver": {**SOLVER, "rtol": rtol},
        "output": {"fields": list(fields), "probes": [list(map(float, p)) for p in probes], "surface": surface},
    }


def _run(spec: dict, mesh: Path | None = None, functions: Functions | None = None):
    return run(spec, mesh, cache=GeometryCache(None), functions=functions)


def _cell_centres(result) -> tuple[np.ndarray, np.ndarray]:
    """(solid mask [*shape], centres [n_solid, d]) of the cells holding material."""
    grid = result.grid
    solid = result.volume_fraction > 0
    idx = np.argwhere(solid)
    return solid, np.asarray(grid.origin) + grid.spacing * (idx + 0.5)


def _voigt(sigma: np.ndarray) -> np.ndarray:
    if len(sigma) == 3:
        return np.array([sigma[0, 0], sigma[1, 1], sigma[2, 2], sigma[1, 2], sigma[0, 2], sigma[0, 1]])
    return np.array([sigma[0, 0], sigma[1, 1], sigma[0, 1]])


# --- 1. uniaxial bar ---------------------------------------------------------------------------


@pytest.mark.parametrize("dim", [3, 2])
@pytest.mark.parametrize("support", ["rollers", "free_sides"])
@pytest.mark.parametrize("solver", ["iterative", "direct"])
def test_grid_aligned_bar_under_end_traction_is_exact(tmp_path, dim, support, solver):
    # Bar [0, L] x [0, W]^(d-1) with L / h and W / h integers: the grid (centred, one padding
    # cell) puts every bar face on a cell face, so all fractions are 0 or 1 (faces 1/2).
    L, W, h = 1.0, 0.25, 1.0 / 32  # 32 x 8 (x 8) cells: > 4000 DOFs in 3D, so multigrid + CG iterate
    E, nu, T = 2.0e5, 0.3, 50.0
    c = np.full(dim, W / 2)
    c[0] = 0.0
    if dim == 3:
        path = tmp_path / "bar.stl"
        trimesh.creation.box(bounds=[[0, 0, 0], [L, W, W]]).export(path)
        geometry, mesh = {"mesh": "bar.stl"}, path
    else:
        geometry, mesh = {"polygon": [[[0, 0], [L, 0], [L, W], [0, W]]]}, None
    free = [None] * dim

    def below(k: int) -> dict:  # the half-space x_k <= 0: the face x_k = 0 (other faces meet it in zero area)
        return {"halfspace": {"point": [0.0] * dim, "normal": np.eye(dim)[k].tolist()}}

    # u_x = 0 on the end face x = 0, held weakly (Nitsche) at its surface points
    boundaries = [
        {"kind": "displacement", "name": "end", "region": below(0), "value": [0.0] + free[1:]},
        # the half-space x >= L holds the end face only: side faces meet it in zero-area slivers
        {"kind": "traction", "name": "pull", "region": {"halfspace": {"point": [L] + [0.0] * (dim - 1),
                                                                      "normal": [-1.0] + [0.0] * (dim - 1)}},
         "value": [T] + [0.0] * (dim - 1)},
    ]
    if support == "rollers":
        # u_k = 0 on the side face x_k = 0 (a roller: the other components stay free)
        c[1:] = 0.0
        for k in range(1, dim):
            value = list(free)
            value[k] = 0.0
            boundaries.append({"kind": "displacement", "name": f"roller{k}", "region": below(k), "value": value})
    # free_sides: translations across the bar and the twist stay free; the loads do no work on
    # them, so the engine solves orthogonal to them -- the symmetric solution below.
    spec = _spec(dim, geometry, {"cell_size": h, "padding": 1},
                 {"youngs_modulus": E, "poisson_ratio": nu}, boundaries,
                 fields=("displacement", "stress"), probes=[[L] + [W / 2] * (dim - 1), [0.3] + [0.1] * (dim - 1)],
                 surface=True, method={"kind": "staggered", "solver": solver})
    result = _run(spec, mesh)
    assert np.all((result.volume_fraction == 0) | (result.volume_fraction == 1))
    assert result.solver.residual <= 1e-12
    if solver == "direct":  # the whole problem factorised (free sides: bordered with their rigid modes)
        assert result.solver.iterations == 1
    elif dim == 3:
        assert result.solver.iterations > 1  # the multigrid hierarchy is exercised, not one direct solve

    # uniaxial stress; plane strain carries sigma_zz = nu T out of plane, so the in-plane moduli change
    Ex, nux = (E, nu) if dim == 3 else (E / (1 - nu**2), nu / (1 - nu))
    strain = np.full(dim, -nux * T / Ex)
    strain[0] = T / Ex

    def exact(x):
        return (x - c) * strain

    solid, x = _cell_centres(result)
    sigma = result.fields.cells["stress"][solid]
    want = np.zeros(sigma.shape[1])
    want[0] = T
    assert np.abs(sigma - want).max() <= 1e-9 * T
    scale = T / Ex * L
    assert np.abs(result.fields.cells["displacement"][solid] - exact(x)).max() <= 1e-9 * scale
    assert np.isnan(result.fields.cells["stress"][~solid]).all()
    probes = result.fields.probes["displacement"]
    np.testing.assert_allclose(probes, exact(result.probe_points), rtol=0, atol=1e-9 * scale)
    # each component depends on its own coordinate only, so even the renormalised interpolation
    # at the surface (inactive samples dropped) is exact
    surf = result.fields.surface["displacement"]
    assert np.abs(surf - exact(result.surface_vertices)).max() <= 1e-9 * scale


# --- 1b. the same pull with the bar's sides inside cells -----------------------------------------


def _cut_side_pull(method: dict, h: float) -> float:
    """Largest relative error of the axial strain eps_xx = T / E (differences of u_x between probes
    at x = 0.2 ... 0.8 m, on the axis and near two edges) of the bar [0, 1] x [0, W]^2, W = 0.25 m,
    translated by h (0, 0.2, 0.1) on a pinned grid: side layers of fill 0.8 / 0.2 and 0.9 / 0.1.
    u_x = 0 held on the end x = 0, the traction T along x on x = 1; the exact field is uniaxial."""
    from engine.grid import Grid
    from verification.stress.running import solve

    L, W, E, nu, T = 1.0, 0.25, 2.0e5, 0.3, 50.0
    corner = np.array([0.0, 0.2 * h, 0.1 * h])
    mesh = trimesh.creation.box(bounds=[corner, corner + [L, W, W]])
    grid = Grid(origin=(-h, -h, -h), spacing=h, shape=(round(L / h) + 3, round(W / h) + 3, round(W / h) + 3))
    xs = np.array([0.2, 0.4, 0.6, 0.8])
    across = [(0.0, 0.0), (0.45 * W, 0.45 * W), (-0.45 * W, 0.3 * W)]
    probes = [[x, corner[1] + W / 2 + dy, corner[2] + W / 2 + dz] for x in xs for dy, dz in across]
    boundaries = [
        {"kind": "displacement", "name": "end", "region": {"halfspace": {"point": [0, 0, 0], "normal": [1, 0, 0]}},
         "value": [0.0, None, None]},
        {"kind": "traction", "name": "pull", "region": {"halfspace": {"point": [L, 0, 0], "normal": [-1, 0, 0]}},
         "value": [T, 0.0, 0.0]},
    ]
    spec = _spec(3, {"mesh": "bar.stl"}, {"cell_size": h, "padding": 1}, {"youngs_modulus": E, "poisson_ratio": nu},
                 boundaries, probes=probes, method=method)
    ux = solve(spec, mesh, grid=grid, condition=False).probe().reshape(len(xs), len(across), 3)[..., 0]
    strain = np.diff(ux, axis=0) / np.diff(xs)[:, None]
    return float(np.abs(strain / (T / E) - 1).max())


@pytest.mark.parametrize("method, h", [
    pytest.param({"kind": "staggered"}, 1 / 32, marks=pytest.mark.xfail(strict=True, raises=AssertionError, reason=(
        "measured strain error 6.78e-5 at h = W/4 and 4.10e-5 at W/8 with the loads spread by the energy's own "
        "weights (7.96e-4 and 1.41e-4, second order, with the multilinear interpolation's transpose, which spread "
        "each point's force over two rows where the energy gives each row its solid area; 1.06e-3 at W/4 before the "
        "partial layers' moved weights and their end loads, flat_layers.py; 4.26e-2 and 1.05e-2 before every "
        "body's load got the couple restoring its first moments). What is left: without the partial layers and the "
        "couple 2.05e-5 and 2.03e-5, not zero either (a prototype; docs/benchmarks.md, 'A constant stress given as "
        "tractions')"))),
    ({"kind": "dg", "degree": 1}, 1 / 8),
])
def test_bar_with_its_sides_inside_cells_under_end_traction_is_exact(method, h):
    assert _cut_side_pull(method, h) <= 1e-9


def test_staggered_bar_with_cut_sides_is_within_1e_4():
    # measured 6.78e-5 and 4.10e-5 with the loads spread by the energy's own weights (7.96e-4 and 1.41e-4
    # with the interpolation's transpose; 1.06e-3 and 1.42e-4 before flat_layers.py; 4.26e-2 and 1.05e-2
    # when only free bodies' loads got their moment couple); the exactness the DG row has is the xfail above
    coarse, fine = _cut_side_pull({"kind": "staggered"}, 1 / 16), _cut_side_pull({"kind": "staggered"}, 1 / 32)
    assert coarse < 1e-4 and fine < 6e-5, (coarse, fine)


# --- 2. affine patch test on a cut-cell body ---------------------------------------------------


def _sphere_body(tmp_path):
    centre = np.array([0.1, -0.05, 0.03])  # off the grid's symmetry
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    mesh.apply_translation(centre)
    path = tmp_path / "sphere.stl"
    mesh.export(path)
    inscribed = float(np.einsum("ij,ij->i", mesh.face_normals, mesh.triangles_center - centre).min())
    # distance below the surface of a point: inscribed radius minus its radius (a lower bound)
    depth = lambda x: inscribed - np.linalg.norm(x - centre, axis=1)  # noqa: E731
    return {"mesh": "sphere.stl"}, path, depth, 2.0


def _square_body(tmp_path):
    angle = 0.37
    R = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    corners = np.array([[0, 0], [1.0, 0], [1.0, 1.0], [0, 1.0]]) @ R.T + [0.2, -0.1]
    normals = np.array([[0, -1.0], [1.0, 0], [0, 1.0], [-1.0, 0]]) @ R.T  # outward, edge k from corner k
    depth = lambda x: np.min(np.einsum("kj,kj->k", normals, corners)[None] - x @ normals.T, axis=1)  # noqa: E731
    return {"polygon": [corners.tolist()]}, None, depth, float(np.ptp(corners, axis=0).max())


@pytest.mark.parametrize("dim", [3, 2])
def test_affine_displacement_held_on_the_whole_cut_surface_to_second_order(tmp_path, rng, dim):
    """An affine displacement held (Nitsche) on the whole surface of a body the grid cuts. Full
    cells annihilate affine fields, but the hold's flux is a surface quadrature of sigma n while
    the cut cells' energy gives the divergence form's forces: they differ by O(h) on the cut rows,
    so the field is reproduced to O(h^2) (not to round-off, as a hold of whole sample layers did).
    Measured (error over |G| * extent): 3D res 16: full cells 1.26e-2 max (3.2 h^2), median of all
    cells 2.1e-3 (0.55 h^2); 2D res 24: full cells 2.2e-3 (1.24 h^2); the largest, 9e-2, at cells
    holding 0.2% material (their centre value averages extrapolated samples)."""
    geometry, mesh, depth, extent = (_sphere_body if dim == 3 else _square_body)(tmp_path)
    res = 16 if dim == 3 else 24
    E, nu = 3.0e6, 0.27
    G = rng.normal(size=(dim, dim)) * 1e-3
    shift = rng.normal(size=dim) * 1e-3
    spec = _spec(dim, geometry, {"resolution": res, "padding": 1}, {"youngs_modulus": E, "poisson_ratio": nu},
                 [{"kind": "displacement", "name": "skin", "region": {"all": True}, "value": [0.0] * dim}],
                 fields=("displacement", "stress"))
    functions = Functions(displacement={"skin": lambda x: x @ G.T + shift})
    result = _run(spec, mesh, functions)
    assert result.solver.residual <= 1e-10
    solid, x = _cell_centres(result)
    fraction = result.volume_fraction[solid]
    assert np.any(fraction < 1)  # cut cells
    u = result.fields.cells["displacement"][solid]
    err = np.linalg.norm(u - (x @ G.T + shift), axis=1) / (np.abs(G).max() * extent)
    h_rel = 1.0 / res
    assert err[fraction == 1].max() <= 4.0 * h_rel**2, err[fraction == 1].max()  # 3D 3.2, 2D 1.24 h^2
    assert np.median(err) <= 0.7 * h_rel**2, np.median(err)
    # constant strain in the full cells away from the surface
    lam, mu = lame_parameters(E, nu)
    eps = 0.5 * (G + G.T)
    want = _voigt(lam * np.trace(eps) * np.eye(dim) + 2 * mu * eps)
    inner = (fraction == 1) & (depth(x) > 2 * extent / res)
    sigma = result.fields.cells["stress"][solid][inner]
    assert np.abs(sigma - want).max() <= 0.1 * np.abs(want).max(), np.abs(sigma - want).max() / np.abs(want).max()


# --- 3. Lame thick sphere ----------------------------------------------------------------------


def test_lame_thick_sphere_under_internal_pressure_converges_at_second_order(tmp_path):
    a, b, p = 0.5, 1.0, 1.0e4
    E, nu = 1.0e7, 0.3
    outer = trimesh.creation.icosphere(subdivisions=4, radius=b)
    inner = trimesh.creation.icosphere(subdivisions=4, radius=a)
    inner.invert()
    shell = trimesh.util.concatenate([outer, inner])
    assert shell.is_watertight
    path = tmp_path / "shell.stl"
    shell.export(path)
    # radii of spheres with the facetted volumes (the facets sit up to 0.1% inside the sphere)
    a_eff = (3 * abs(inner.volume) / (4 * np.pi)) ** (1 / 3)
    b_eff = (3 * outer.volume / (4 * np.pi)) ** (1 / 3)

    def u_r(r):
        return p * a_eff**3 / (E * (b_eff**3 - a_eff**3)) * ((1 - 2 * nu) * r + (1 + nu) * b_eff**3 / (2 * r**2))

    gen = np.random.default_rng(5)
    direction = gen.normal(size=(64, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    radius = gen.uniform(a + 0.1, b - 0.1, size=64)
    probes = direction * radius[:, None]
    exact = u_r(radius)

    spacings, errors = [], []
    for res in (12, 16, 24):
        spec = _spec(3, {"mesh": "shell.stl"}, {"resolution": res, "padding": 1},
                     {"youngs_modulus": E, "poisson_ratio": nu},
                     [{"kind": "pressure", "name": "inner", "region": {"sphere": {"center": [0, 0, 0], "radius": 0.75}},
                       "value": p}],
                     probes=probes, rtol=1e-10)
        result = _run(spec, path)
        # no displacement boundary: all six rigid modes float, the pressure balances them
        assert any("6 rigid-body mode(s)" in w for w in result.solver.warnings)
        u = result.fields.probes["displacement"]
        radial = np.einsum("ij,ij->i", u, direction)
        tangential = np.linalg.norm(u - radial[:, None] * direction, axis=1)
        err = np.abs(radial - exact).max() / exact.max()
        assert tangential.max() <= 2 * err * exact.max()
        spacings.append(result.grid.spacing)
        errors.append(err)
    order = np.polyfit(np.log(spacings), np.log(errors), 1)[0]
    # measured: errors 0.063, 0.036, 0.0165 (h = 1/6, 1/8, 1/12), fitted order 1.93
    assert order >= 1.5, (spacings, errors)
    assert errors[-1] <= 0.025 and errors[0] > errors[1] > errors[2]


# --- 4. quasi-static ramp -------------------------------------------------------------------------


def test_quasistatic_steps_are_the_static_solution_scaled():
    spec = json.loads((ROOT / "examples" / "cantilever.json").read_text())
    spec["grid"] = {"resolution": 32, "padding": 1}
    spec["solver"] = {**SOLVER, "rtol": 1e-10}
    spec["output"]["fields"] = ["displacement", "stress"]
    mesh = ROOT / "examples" / "cantilever.stl"
    static = _run(spec, mesh)
    ramp = _run({**spec, "analysis": {"kind": "quasistatic", "steps": 3}}, mesh)
    assert [s.time for s in ramp.steps] == pytest.approx([1 / 3, 2 / 3, 1.0], abs=1e-15)
    solid = np.isfinite(static.fields.cells["displacement"][..., 0])
    assert solid.sum() > 1000
    for name in ("displacement", "stress"):
        ref = static.fields.cells[name][solid]
        scale = np.abs(ref).max()
        for k, step in enumerate(ramp.steps):
            got = step.cells[name][solid]
            assert np.abs(got - (k + 1) / 3 * ref).max() <= 1e-6 * scale, (name, k)
        assert np.abs(ramp.fields.cells[name][solid] - ref).max() <= 1e-6 * scale
    tip = static.fields.probes["displacement"][0]
    for k, step in enumerate(ramp.steps):
        assert np.abs(step.probes["displacement"][0] - (k + 1) / 3 * tip).max() <= 1e-6 * np.abs(tip).max()


# --- 5. dynamics of a bar -----------------------------------------------------------------------


def _bar_dynamics(tmp_path, dt, steps, method=None):
    # nu = 0: lambda = 0 and the axial motion u_x(x, t) is exactly 1D on the grid (no lateral
    # coupling); rho, E give c = 4 m/s, so the period 4 L / c of the clamped-free bar is 1 s.
    L, W, h = 1.0, 0.1, 0.05
    rho, c, traction = 1000.0, 4.0, 16.0
    E = rho * c**2
    path = tmp_path / "rod.stl"
    if not path.exists():
        trimesh.creation.box(bounds=[[0, 0, 0], [L, W, W]]).export(path)
    spec = _spec(3, {"mesh": "rod.stl"}, {"cell_size": h, "padding": 1},
                 {"youngs_modulus": E, "poisson_ratio": 0.0, "density": rho},
                 [  # the end face only (clamped sides near it would shear the section)
                     {"kind": "displacement", "name": "clamp", "value": [0, 0, 0],
                      "region": {"box": [[-1, -1, -1], [1e-9, 1, 1]]}},
                     {"kind": "traction", "name": "pull",
                      "region": {"halfspace": {"point": [L, 0, 0], "normal": [-1, 0, 0]}}, "value": [traction, 0, 0]},
                 ],
                 analysis={"kind": "dynamic", "time_step": dt, "steps": steps}, probes=[[L, W / 2, W / 2]], rtol=1e-10,
                 method=method)
    result = _run(spec, path)
    times = np.array([s.time for s in result.steps])
    tip = np.array([s.probes["displacement"][0] for s in result.steps])
    return result, times, tip, traction * L / E, 4 * L / c


BAR_METHODS = [None, {"kind": "dg", "degree": 1}, {"kind": "dg", "degree": 2}]


@pytest.mark.parametrize("method", BAR_METHODS, ids=["staggered", "dg1", "dg2"])
def test_bar_under_sudden_end_load_oscillates_with_the_period_4L_over_c(tmp_path, method):
    period = 1.0
    result, t, tip, static, period = _bar_dynamics(tmp_path, period / 200, 320, method)
    np.testing.assert_allclose(t, period / 200 * np.arange(1, 321), rtol=1e-12)
    # nu = 0: no lateral motion. DG: the penalty per unit area is larger on the half-cut pieces of the
    # section than on its full cells, so the discrete section is not uniform (measured 2.5e-6 k = 2; k = 1
    # 1.5e-4, 5.8e-5 with its whole jump penalised: the rotations of its elements are softer, JUMP_REST)
    # staggered: the STL's float32 faces (0.1 m stored as 0.1000000015) give the two side layers fills
    # 3e-8 apart, which the partial layers' moved weights follow (flat_layers.py): 2.3e-10 measured
    limit = {None: 1e-9, 1: 3e-4, 2: 1e-4}[None if method is None else method["degree"]]
    assert np.abs(tip[:, 1:]).max() <= limit * static
    u = tip[:, 0] / static
    # step load from rest: the tip swings between 0 and twice the static displacement
    assert 1.7 <= u[:200].max() <= 2.0 and u[150:250].min() <= 0.3 and u.min() >= -0.05
    first = np.argmax(u[:150])
    second = 150 + np.argmax(u[150:])
    assert abs((t[second] - t[first]) - period) <= 0.05 * period  # measured: 1.000 (both maxima on steps)
    # crossings of the static value, linearly interpolated: T/4, 3T/4, 5T/4
    z = u - 1.0
    k = np.nonzero(np.sign(z[:-1]) != np.sign(z[1:]))[0]
    crossings = t[k] - z[k] * (t[k + 1] - t[k]) / (z[k + 1] - z[k])
    assert len(crossings) >= 3
    assert abs((crossings[2] - crossings[0]) - period) <= 0.05 * period  # measured: 1.0001
    assert abs(crossings[0] - period / 4) <= 0.05 * period


@pytest.mark.parametrize("method", BAR_METHODS, ids=["staggered", "dg1", "dg2"])
def test_bar_with_large_backward_euler_steps_relaxes_to_the_static_solution(tmp_path, method):
    result, t, tip, static, period = _bar_dynamics(tmp_path, 1.0, 5, method)
    np.testing.assert_allclose(t, np.arange(1, 6), rtol=1e-12)
    u = tip[:, 0] / static
    assert np.all(np.isfinite(tip)) and np.all(np.abs(u) <= 2.0)
    for step in result.steps:
        disp = step.cells["displacement"]
        assert np.all(np.isfinite(disp[result.volume_fraction > 0]))
    # measured: 0.9796, 1.0194, 1.0014, 0.99960, 0.99994
    error = np.abs(u - 1.0)
    assert error[-1] <= 1e-3 and error[-1] <= 0.1 * error[0] and error[-1] <= 0.1 * error[1]
