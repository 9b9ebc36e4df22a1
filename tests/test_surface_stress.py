"""Stresses users can trust (issue 19), the staggered side and what both methods share: strains
fitted where they are asked for (engine/staggered/recovery.py), the surface stress that carries the
applied tractions (engine/surface_stress.py) and the reported peak (engine/peaks.py).

The thick sphere: a = 0.5, b = 1 m (facetted: the volume-equivalent radii of verification.problems
"lame"), E = 1e7 Pa, nu = 0.3, internal pressure 1e4 Pa, free body; the exact von Mises is
sqrt(3) mu |B| ... (verification.problems), 1.7143e4 Pa on the inner surface and 2.143e3 Pa on the
outer one for the true radii.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import h5py
import numpy as np
import pytest
import trimesh

from engine import simulate
from engine.boundary import Prescribed, SurfaceLoad
from engine.geometry.cache import GeometryCache
from engine.geometry.surface import Surface
from engine.output import write_result
from engine.peaks import peaks
from engine.regions import make_region
from schemas import parse_job
from engine.surface_stress import facet_tractions, from_voigt, recover, to_voigt
from verification.problems import lame_problem, problem


def region(spec: dict):
    """A 3D region from its job-spec form."""
    job = parse_job({"dimension": 3, "geometry": {"mesh": "m.stl"}, "grid": {"resolution": 8},
                     "material": {"youngs_modulus": 1.0, "poisson_ratio": 0.3},
                     "boundaries": [{"kind": "displacement", "name": "r", "region": spec, "value": [0, 0, 0]}]})
    return make_region(job.boundaries[0].region, 3)


def sphere_probes(n: int = 500) -> np.ndarray:
    x = np.random.default_rng(5).uniform(-1, 1, (40000, 3))
    r = np.linalg.norm(x, axis=1)
    return x[(r > 0.62) & (r < 0.88)][:n]


def run_sphere(method: dict, h: float, probes: np.ndarray):
    pb = problem("lame")
    spec, mesh, functions = pb.job(method, h)
    spec["output"].update(probes=probes.tolist(), fields=["von_mises", "stress"], surface=True)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "shell.ply"  # binary PLY keeps float64 vertices
        mesh.export(path)
        spec["geometry"]["mesh"] = path.name
        return pb, simulate(spec, path, cache=GeometryCache(None), functions=functions)


def test_staggered_von_mises_at_probes_is_second_order_and_the_surface_within_3_percent():
    """Measured: probe von Mises relative L2 2.99e-2, 3.62e-3, 9.01e-4 at h = 1/10, 1/20, 1/40
    (order 2.5; taking the cell's value gave 1.20e-1, 6.21e-2, order 1.0). Surface von Mises at
    h = 1/40 over the exact: inner max 1.012, mean 0.983; outer max 1.009, mean 0.982."""
    probes = sphere_probes()
    errors = []
    for h in (0.1, 0.05, 0.025):
        pb, result = run_sphere({"kind": "staggered"}, h, probes)
        vm = result.fields.probes["von_mises"]
        assert np.all(np.isfinite(vm))
        exact = pb.von_mises(probes)
        errors.append(float(np.sqrt(np.sum((vm - exact) ** 2) / np.sum(exact**2))))
    order = np.polyfit(np.log([0.1, 0.05, 0.025]), np.log(errors), 1)[0]
    assert order >= 1.8 and errors[-1] < 1.5e-2, errors
    v = result.surface_vertices
    r = np.linalg.norm(v, axis=1)
    surface_vm = result.fields.surface["von_mises"]
    for side in (r < 0.75, r > 0.75):
        exact = pb.von_mises(v[side]).mean()
        assert abs(surface_vm[side].max() / exact - 1) < 0.03
        assert abs(surface_vm[side].mean() / exact - 1) < 0.03


def bar_job(method: dict, h: float) -> tuple[dict, bytes]:
    """A 2 x 0.5 x 0.5 m bar on grid planes, pulled by 1e3 Pa on both end faces (a free body in
    uniaxial tension); its mesh subdivided so the sides have vertices of their own."""
    box = trimesh.creation.box(bounds=[[0, 0, 0], [2.0, 0.5, 0.5]]).subdivide().subdivide()
    spec = {"dimension": 3, "geometry": {"mesh": "bar.stl"}, "method": method,
            "grid": {"cell_size": h, "padding": 1},
            "material": {"youngs_modulus": 1e7, "poisson_ratio": 0.3},
            "boundaries": [
                {"kind": "traction", "name": "right", "value": [1e3, 0, 0],
                 "region": {"halfspace": {"point": [1.99, 0, 0], "normal": [-1, 0, 0]}},
                 "facing": {"direction": [1, 0, 0], "max_angle_deg": 30}},
                {"kind": "traction", "name": "left", "value": [-1e3, 0, 0],
                 "region": {"halfspace": {"point": [0.01, 0, 0], "normal": [1, 0, 0]}},
                 "facing": {"direction": [-1, 0, 0], "max_angle_deg": 30}}],
            "solver": {"rtol": 1e-12},
            "output": {"fields": ["stress", "von_mises"], "surface": True}}
    return spec, box.export(file_type="stl")


STAGGERED, DG1, DG2 = {"kind": "staggered"}, {"kind": "dg", "degree": 1}, {"kind": "dg", "degree": 2}


@pytest.mark.parametrize("method", [STAGGERED, DG1, DG2], ids=["staggered", "dg1", "dg2"])
def test_surface_stress_of_a_bar_in_uniaxial_tension_is_uniform(method):
    """Patch test, every method: the solution is the exact affine field, and the surface stress is
    sigma_xx = 1e3 Pa, the rest zero, to round-off."""
    spec, mesh = bar_job(method, 0.125)
    result = simulate(spec, mesh, filename="bar.stl", cache=GeometryCache(None))
    s = result.fields.surface["stress"]
    assert s.shape == (len(result.surface_vertices), 6)
    want = np.array([1e3, 0, 0, 0, 0, 0])
    np.testing.assert_allclose(s, np.broadcast_to(want, s.shape), atol=1e-6 * 1e3)
    np.testing.assert_allclose(result.fields.surface["von_mises"], 1e3, rtol=1e-9)


def facetted_shell(subdivisions: int = 4) -> Surface:
    outer = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    inner = trimesh.creation.icosphere(subdivisions=subdivisions, radius=0.5)
    inner.invert()
    mesh = trimesh.util.concatenate([outer, inner])
    return Surface(vertices=np.asarray(mesh.vertices, float), faces=np.asarray(mesh.faces))


def test_recovery_keeps_the_tangential_stress_of_a_pressurised_facetted_sphere():
    """The exact Lame stress at the vertices of facetted spheres (a = 0.5, b = 1) with its normal rows
    spoiled (as a one-sided fit may give them) comes back to the exact one: sigma n = -p n puts the
    normal rows back and the hoop stress is kept (asking -p n of every tilted facet would have
    pinned it to -p as well). The pressure is taken at each vertex's normal: the mean of the facets'
    -p n_f fell short of -p n by their spread (1.05e-3 p here, 4.1e-3 at subdivision 3)."""
    pb = lame_problem(0.5, 1.0, 1e4, 1e7, 0.3, probes=np.zeros((1, 3)))
    surface = facetted_shell()
    v = surface.vertices
    exact = pb.stress(v)
    n = v / np.linalg.norm(v, axis=1, keepdims=True)
    spoiled = exact + 0.2 * pb.pressure * (n[:, :, None] * n[:, None, :])
    load = SurfaceLoad(region=region({"sphere": {"center": [0, 0, 0], "radius": 0.75}}), name="inner",
                       pressure=pb.pressure)
    got = recover(surface, spoiled, facet_tractions(surface, [load], []))
    err = np.abs(got - exact).max() / pb.pressure
    assert err < 1e-6, err  # measured 1.0e-8: the conditions' weight 1e8 in the normal equations
    every_facet = recover(surface, spoiled, facet_tractions(surface, [load], []), feature_angle=0.0)
    assert np.abs(every_facet - exact).max() / pb.pressure > 0.1  # the hoop stress pinned


def test_recovery_at_a_free_box_corner_zeroes_every_stress_and_held_facets_add_nothing():
    box = trimesh.creation.box(bounds=[[0, 0, 0], [1, 1, 1]])
    corners = Surface(vertices=np.asarray(box.vertices, float), faces=np.asarray(box.faces))
    raw = np.broadcast_to(np.array([[1.0, 0.2, 0.3], [0.2, 2.0, 0.4], [0.3, 0.4, 3.0]]), (8, 3, 3))
    free = recover(corners, raw, facet_tractions(corners, [], []))
    assert np.abs(free).max() < 1e-6  # three free faces meet at every corner: sigma = 0
    held = Prescribed(region=region({"all": True}), name="clamp", value=(0, 0, 0))
    np.testing.assert_allclose(recover(corners, raw, facet_tractions(corners, [], [held])), raw, rtol=1e-12)
    # inside a flat free face (x = 0, the rest held) the x row is replaced, the in-plane stresses kept
    fine = box.subdivide().subdivide().subdivide()
    surface = Surface(vertices=np.asarray(fine.vertices, float), faces=np.asarray(fine.faces))
    m = len(surface.vertices)
    raw = np.broadcast_to(raw[0], (m, 3, 3))
    rest = Prescribed(region=region({"halfspace": {"point": [0.25, 0, 0], "normal": [-1, 0, 0]}}),
                      name="rest", value=(0, 0, 0))
    got = recover(surface, raw, facet_tractions(surface, [], [rest]))
    v = surface.vertices
    at = np.nonzero((v[:, 0] == 0) & np.all((v[:, 1:] > 0) & (v[:, 1:] < 1), axis=1))[0]
    assert len(at) > 10
    np.testing.assert_allclose(got[at][:, 0, :], 0.0, atol=1e-6)
    np.testing.assert_allclose(got[at][:, 1:, 1:], raw[at][:, 1:, 1:], rtol=1e-6)


def test_voigt_round_trip():
    s = np.random.default_rng(1).standard_normal((4, 6))
    np.testing.assert_array_equal(to_voigt(from_voigt(s, 3)), s)


@pytest.mark.parametrize("method", [STAGGERED, DG2], ids=["staggered", "dg2"])
def test_the_peak_is_reported_in_the_result_file_and_sits_where_the_stress_is_largest(tmp_path, method):
    spec, mesh = bar_job(method, 0.125)
    # hold the left end instead: bending under a transverse tip load puts the peak at the root
    spec["boundaries"][1] = {"kind": "displacement", "name": "left", "value": [0, 0, 0],
                             "region": {"halfspace": {"point": [0.01, 0, 0], "normal": [1, 0, 0]}}}
    spec["boundaries"][0]["value"] = [0, 0, -1e3]
    result = simulate(spec, mesh, filename="bar.stl", cache=GeometryCache(None))
    found = peaks(result)
    assert set(found) == {"surface", "volume"}
    cells = result.fields.cells["von_mises"]
    assert found["volume"].value == pytest.approx(np.nanmax(cells[result.volume_fraction >= 0.5]), rel=1e-12)
    assert found["surface"].value >= np.nanmax(result.fields.surface["von_mises"]) * (1 - 1e-12)
    assert found["surface"].location[0] < 0.5 and found["volume"].location[0] < 0.5  # near the root
    # beam theory at the root: M c / I = (1e3 * 0.25) * 2 * 0.25 / (0.5^4 / 12) = 2.4e4 Pa
    assert 0.7 < found["surface"].value / 2.4e4 < 1.6, found["surface"].value
    path = write_result(result, tmp_path / "bar.h5")
    with h5py.File(path) as f:
        g = f["peak"]
        assert g.attrs["units"] == "Pa"
        assert g.attrs["surface_von_mises"] == pytest.approx(found["surface"].value)
        np.testing.assert_allclose(g.attrs["volume_location"], found["volume"].location)


@pytest.mark.parametrize("method", [STAGGERED, DG2], ids=["staggered", "dg2"])
def test_quasistatic_steps_carry_their_own_load_on_the_surface(method):
    """Each load step's surface stress carries that step's traction: sigma_xx = k / n * 1e3 Pa."""
    spec, mesh = bar_job(method, 0.125)
    spec["analysis"] = {"kind": "quasistatic", "steps": 4}
    result = simulate(spec, mesh, filename="bar.stl", cache=GeometryCache(None))
    assert len(result.steps) == 4
    for k, step in enumerate(result.steps, start=1):
        s = step.surface["stress"]
        np.testing.assert_allclose(s[:, 0], 1e3 * k / 4, rtol=1e-9)
        np.testing.assert_allclose(s[:, 1:], 0.0, atol=1e-6)


def test_recovery_on_a_cylinder_rim_keeps_the_hoop_stress():
    """Where a facetted cylinder's wall meets its end face, the wall's facets (turning 5.6 degrees
    each) are one face: sigma n = 0 with their mean normal and with the end's normal zero what the
    two faces say and keep the hoop stress (a condition per wall facet would zero it too)."""
    cyl = trimesh.creation.cylinder(radius=1.0, height=1.0, sections=64)
    surface = Surface(vertices=np.asarray(cyl.vertices, float), faces=np.asarray(cyl.faces))
    v = surface.vertices
    rim = np.nonzero(np.abs(np.hypot(v[:, 0], v[:, 1]) - 1.0) < 1e-9)[0]
    hoop = np.stack([-v[:, 1], v[:, 0], np.zeros(len(v))], axis=1)
    radial = np.stack([v[:, 0], v[:, 1], np.zeros(len(v))], axis=1)
    want = hoop[:, :, None] * hoop[:, None, :]
    raw = want + 0.3 * (radial[:, :, None] * radial[:, None, :]) + 0.2 * np.eye(3)[2]  # spoiled rows
    got = recover(surface, raw, facet_tractions(surface, [], []))
    assert np.abs(got[rim] - want[rim]).max() < 1e-6  # measured 8.8e-9
    per_facet = recover(surface, raw, facet_tractions(surface, [], []), feature_angle=0.0)
    assert np.abs(per_facet[rim] - want[rim]).max() > 0.9  # the hoop stress zeroed


@pytest.mark.parametrize("method", [STAGGERED, DG1, DG2], ids=["staggered", "dg1", "dg2"])
def test_a_free_torus_under_pressure_is_hydrostatic_in_its_cells_and_on_its_facetted_surface(method):
    """Patch test on a curved, facetted surface: pressure p on all of a free torus gives sigma = -p I
    everywhere. The cells have it to round-off; the surface (before: 9.6e-3 p off where the facets
    turn) to the recovery's 1e-8."""
    torus = trimesh.creation.torus(major_radius=0.6, minor_radius=0.25, major_sections=24, minor_sections=12)
    p = 1e3
    spec = {"geometry": {"mesh": "torus.stl"}, "grid": {"resolution": 16 if method is STAGGERED else 8},
            "method": method, "material": {"youngs_modulus": 1e6, "poisson_ratio": 0.3},
            "boundaries": [{"kind": "pressure", "name": "all", "region": {"box": [[-2, -2, -2], [2, 2, 2]]},
                            "value": p}],
            "solver": {"rtol": 1e-12}, "output": {"fields": ["stress", "pressure"], "surface": True}}
    result = simulate(spec, torus.export(file_type="stl"), filename="torus.stl", cache=GeometryCache(None))
    want = np.array([-p, -p, -p, 0, 0, 0])
    cells = result.fields.cells["stress"]
    cells = cells[np.isfinite(cells).all(axis=-1)]
    np.testing.assert_allclose(cells, np.broadcast_to(want, cells.shape), atol=1e-10 * p)
    surface = result.fields.surface["stress"]
    np.testing.assert_allclose(surface, np.broadcast_to(want, surface.shape), atol=1e-6 * p)
    np.testing.assert_allclose(result.fields.surface["pressure"], p, rtol=1e-6)


@pytest.mark.parametrize("method", [STAGGERED, DG1], ids=["staggered", "dg1"])
def test_the_volume_peak_of_a_uniform_pull_is_not_a_sliver_cells_extrapolation(method):
    """A cylinder pulled by T on its end caps is at sigma_zz = T everywhere. Staggered cut cells of fill
    down to 0.009 where the caps meet the side took 2.41 T (a /tmp script at commit 4c28246: 1.48 T off
    in some cell, 1.094 T the volume peak over the cells at least half solid) while the caps' tractions
    were spread by the interpolation's transpose; spread as the energy takes a stress they hold T in
    every cell to 1.2e-12 (the volume peak still counts the cells at least half solid only). DG: T to
    round-off."""
    cylinder = trimesh.creation.cylinder(radius=0.25, height=1.2, sections=32)
    t = 1e3
    ends = [{"kind": "traction", "name": f"end{s}", "region": {"halfspace": {"point": [0, 0, 0.55 * s], "normal": [0, 0, -s]}},
             "facing": {"direction": [0, 0, s], "max_angle_deg": 5}, "value": [0, 0, s * t]} for s in (1, -1)]
    spec = {"geometry": {"mesh": "cylinder.stl"}, "grid": {"resolution": 48 if method is STAGGERED else 10},
            "method": method, "material": {"youngs_modulus": 1e6, "poisson_ratio": 0.3}, "boundaries": ends,
            "solver": {"rtol": 1e-12}, "output": {"fields": ["von_mises", "stress"], "surface": True}}
    result = simulate(spec, cylinder.export(file_type="stl"), filename="cylinder.stl", cache=GeometryCache(None))
    found = peaks(result)
    stress = result.fields.cells["stress"].reshape(-1, 6)
    stress = stress[np.isfinite(stress).all(axis=1)]
    assert np.abs(stress - [0, 0, t, 0, 0, 0]).max() < 1e-9 * t  # slivers included
    assert found["volume"].value == pytest.approx(t, rel=1e-9)
    assert found["surface"].value == pytest.approx(t, rel=1e-6)
