"""Boundaries act on their surface patch, in both methods alike (README, "What works today").

The staggered method holds a displacement patch weakly (Nitsche's method at the patch's surface
points, engine/staggered/nitsche.py), DG likewise; both take their patches, loads and errors from
engine/boundary.py.
"""

import numpy as np
import pytest
import trimesh

from engine import simulate
from engine.boundary import Facing, select_patch, surface_quadrature
from engine.errors import BoundaryError
from engine.pipeline import Functions
from engine.regions import Halfspaces
from tests.conftest import surface_of
from verification.held import clamped_sphere_error

L, W = 10.0, 1.0
E, NU, RHO, G = 1.0e9, 0.3, 1000.0, 9.81


def bar_job(method: dict, h: float, boundaries: list, *, gravity=(0.0, 0.0, -G), probes=None) -> dict:
    return {"dimension": 3, "geometry": {"mesh": "bar.stl"}, "grid": {"cell_size": h, "padding": 1}, "method": method,
            "material": {"youngs_modulus": E, "poisson_ratio": NU, "density": RHO}, "loads": {"gravity": list(gravity)},
            "boundaries": boundaries, "solver": {"rtol": 1e-10},
            "output": {"fields": ["displacement"], "probes": probes or [[L - 1e-3, 0.0, 0.0]], "surface": False}}


def bar_stl() -> bytes:
    return trimesh.creation.box(bounds=[[0, -W / 2, -W / 2], [L, W / 2, W / 2]]).export(file_type="stl")


def timoshenko_gravity_tip() -> float:
    """Tip deflection [m] of the clamped bar under its weight: q L^4 / 8EI + q L^2 / (2 kappa G A)."""
    q, inertia = RHO * G * W * W, W**4 / 12
    shear = E / (2 * (1 + NU))
    kappa = 10 * (1 + NU) / (12 + 11 * NU)
    return q * L**4 / (8 * E * inertia) + q * L**2 / (2 * kappa * shear * W * W)


CLAMP = {"kind": "displacement", "name": "clamp", "region": {"box": [[-1, -2, -2], [0.1, 2, 2]]}, "value": [0, 0, 0]}


def test_a_clamp_thinner_than_a_cell_holds_the_bar_as_dg_does():
    """The bundled cantilever's shape at 4 cells across, clamped by x <= 0.1 (0.4 h): the staggered
    grid holds the end face and the 0.1 m strips of the sides (it used to refuse the job: the box
    held no u_y, u_z sample). Measured: staggered 0.979, DG k = 2 0.968 of Timoshenko's tip."""
    mesh = bar_stl()
    stag = simulate(bar_job({"kind": "staggered"}, 0.25, [CLAMP]), mesh, filename="bar.stl")
    dg = simulate(bar_job({"kind": "dg", "degree": 2}, 0.25, [CLAMP]), mesh, filename="bar.stl")
    tip_s = -stag.fields.probes["displacement"][0, 2]
    tip_d = -dg.fields.probes["displacement"][0, 2]
    beam = timoshenko_gravity_tip()
    assert abs(tip_s / tip_d - 1) < 0.03, (tip_s, tip_d)
    assert abs(tip_s / beam - 1) < 0.03, (tip_s, beam)
    assert stag.solver.residual <= 1e-10


def test_facing_keeps_only_the_end_face_and_the_load_has_the_exact_resultant():
    """A half-space x >= L - 0.3 takes the end face and 0.3 m strips of the four sides; facing
    +x within 30 degrees keeps the end face alone: its traction's resultant is t * W^2 exactly, in
    the staggered load vector, and DG answers as with a region holding only the end face."""
    mesh = trimesh.creation.box(bounds=[[0, -W / 2, -W / 2], [L, W / 2, W / 2]])
    surface = surface_of(mesh)
    wide = Halfspaces(np.array([[-1.0, 0, 0]]), np.array([-(L - 0.3)]))
    facets = surface.vertices[surface.faces]
    _, w_all, _ = surface_quadrature(select_patch(wide, facets, "t")[0], 0.25)
    assert abs(w_all.sum() - (W * W + 4 * 0.3 * W)) < 1e-12
    pieces, _ = select_patch(Facing(wide, np.array([1.0, 0, 0]), 30.0), facets, "t")
    _, w, _ = surface_quadrature(pieces, 0.25)
    assert abs(w.sum() - W * W) < 1e-12

    t = [0.0, 0.0, -1.0e3]
    region = {"halfspace": {"point": [L - 0.3, 0, 0], "normal": [-1, 0, 0]}}
    faced = {"kind": "traction", "name": "tip", "region": region, "value": t,
             "facing": {"direction": [1, 0, 0], "max_angle_deg": 30}}
    from engine.pipeline import prepare_geometry
    from engine.staggered.problem import make_staggered
    from schemas import parse_job

    spec = parse_job(bar_job({"kind": "staggered"}, 0.25, [CLAMP, faced], gravity=(0, 0, 0)))
    geo = prepare_geometry(spec, bar_stl(), filename="bar.stl")
    method = make_staggered(spec, geo, Functions())
    np.testing.assert_allclose(method.loads.sum(axis=1), np.asarray(t) * W * W, rtol=1e-12, atol=1e-9)

    end_only = {**faced, "region": {"halfspace": {"point": [L, 0, 0], "normal": [-1, 0, 0]}}}
    end_only.pop("facing")
    tips = []
    for b in (faced, end_only):
        r = simulate(bar_job({"kind": "dg", "degree": 1}, 0.5, [CLAMP, b], gravity=(0, 0, 0)), bar_stl(),
                     filename="bar.stl")
        tips.append(r.fields.probes["displacement"][0, 2])
    assert tips[0] < 0 and abs(tips[0] - tips[1]) <= 1e-10 * abs(tips[1])


def _staggered_load_resultant(boundary: dict, functions: Functions) -> np.ndarray:
    from engine.pipeline import prepare_geometry
    from engine.staggered.problem import make_staggered
    from schemas import parse_job

    spec = parse_job(bar_job({"kind": "staggered"}, 0.25, [CLAMP, boundary], gravity=(0, 0, 0)))
    geo = prepare_geometry(spec, bar_stl(), filename="bar.stl")
    return make_staggered(spec, geo, functions).loads.sum(axis=1)


@pytest.mark.parametrize("form", ["divergence", "quadrature"])
def test_a_pressure_acts_on_its_patch_alone_in_either_form(form):
    """A box over the upper half of the bar's end takes that half of the end face (W^2 / 2) and a
    0.3 m strip of the top face (0.3 W); with facing +x only the end's half. The pressure's
    resultant -p sum(n dA) over the patch, from the staggered load vector. The divergence form (the
    default for pressures) used to load every row within h / 2 of the region, with all the surface
    its control volumes hold: (-0.75, 0, -0.5) p against (-0.5, 0, -0.3) p without facing, the same
    with it (the facets facing leaves out were loaded). Measured now: (-0.49995, 0, -0.2984) and
    (-0.49995, 0, 0) p: the rows at the patch's rims keep their patch's share."""
    p = 1.0e3
    region = {"box": [[L - 0.3, -2, 0.0], [L + 1, 2, 2]]}
    pushed = {"kind": "pressure", "name": "push", "region": region, "value": p}
    faced = {**pushed, "facing": {"direction": [1, 0, 0], "max_angle_deg": 30}}
    functions = Functions(pressure_form=form)
    np.testing.assert_allclose(_staggered_load_resultant(pushed, functions) / p, [-W * W / 2, 0, -0.3 * W],
                               atol=2e-3)
    np.testing.assert_allclose(_staggered_load_resultant(faced, functions) / p, [-W * W / 2, 0, 0], atol=1e-4)
    # a Python predicate picks whole facets by their centroid (no slack to widen it by): the end face
    end = Functions(pressure_form=form, regions={"push": lambda x: x[:, 0] >= L - 1e-6})
    np.testing.assert_allclose(_staggered_load_resultant(pushed, end) / p, [-W * W, 0, 0], atol=1e-4)


@pytest.mark.parametrize("thickness, h, facing", [(0.2, 0.125, True), (0.2, 1 / 12, False), (1.0, 1 / 6, False)])
def test_a_pressure_on_part_of_a_surface_has_its_resultant_in_the_divergence_form(thickness, h, facing):
    """The divergence form reads the stress through whole rows; a row that saw the patch and a free
    surface at once lost part of its force: a pressure on the middle of a plate 1.6 cells thick
    loaded 640 of its 800 N (80%), 1.25% too much at 2.4 cells; what it misses of the resultant now
    comes as a uniform traction on the patch (``StaggeredElasticity._divergence_gap``)."""
    from engine.pipeline import prepare_geometry
    from engine.staggered.problem import make_staggered
    from schemas import parse_job

    p = 1.0e4
    mesh = trimesh.creation.box(bounds=[[0, 0, 0], [1, 0.2, thickness]]).export(file_type="stl")
    push = {"kind": "pressure", "name": "push", "value": p,
            "region": {"box": [[0.3, -1, thickness - 0.01 if facing else thickness / 2], [0.7, 1, thickness + 1]]}}
    if facing:
        push["facing"] = {"direction": [0, 0, 1], "max_angle_deg": 10}
    clamp = {"kind": "displacement", "name": "clamp", "region": {"box": [[-1, -1, -1], [0.01, 1, 2]]}, "value": [0, 0, 0]}
    spec = {"dimension": 3, "geometry": {"mesh": "plate.stl"}, "grid": {"cell_size": h, "padding": 1},
            "material": {"youngs_modulus": 1e7, "poisson_ratio": 0.3}, "boundaries": [clamp, push]}
    job = parse_job(spec)
    net = make_staggered(job, prepare_geometry(job, mesh, filename="plate.stl"), Functions()).loads.sum(axis=1)
    # the top (0.4 x 0.2): with the upper halves of the sides, whose forces cancel, when not facing +z
    np.testing.assert_allclose(net, [0, 0, -p * 0.4 * 0.2], atol=1e-6 * p * 0.08)


@pytest.mark.parametrize("method", [{"kind": "staggered"}, {"kind": "dg", "degree": 1}])
def test_a_region_without_surface_is_an_error_naming_it_and_the_gap(method):
    far = {"kind": "displacement", "name": "far clamp", "region": {"box": [[-3, -2, -2], [-1, 2, 2]]}, "value": [0, 0, 0]}
    with pytest.raises(BoundaryError, match=r"far clamp: the region holds no part of the mesh surface \(its region "
                                            r"is 1 m from the nearest surface vertex\)"):
        simulate(bar_job(method, 0.5, [far]), bar_stl(), filename="bar.stl")


@pytest.mark.parametrize("method", [{"kind": "staggered"}, {"kind": "dg", "degree": 1}])
def test_two_holds_that_disagree_on_a_common_patch_are_an_error_naming_both(method):
    end = {"kind": "displacement", "name": "pull", "region": {"box": [[L - 0.1, -2, -2], [L + 1, 2, 2]]},
           "value": [1e-3, None, None]}
    everywhere = {"kind": "displacement", "name": "glue", "region": {"all": True}, "value": [0, 0, 0]}
    with pytest.raises(BoundaryError, match=r"glue and pull: both prescribe u_x on the same 1.4 m\^2 of the surface, "
                                            r"with different values there \(0 and 0.001 m\)"):
        simulate(bar_job(method, 0.5, [everywhere, end]), bar_stl(), filename="bar.stl")
    # what may overlap: equal values (two clamps), other components (a roller), regions that only touch
    roller = {"kind": "displacement", "name": "roller", "region": {"box": [[-1, -2, -2], [0.5, 2, 2]]},
              "value": [None, 0, None]}
    touching = {**end, "name": "lift", "region": {"box": [[0.1, -2, -2], [0.3, 2, 2]]}, "value": [None, None, 2e-3]}
    r = simulate(bar_job(method, 0.5, [CLAMP, {**CLAMP, "name": "clamp 2"}, roller, touching], gravity=(0, 0, 0)),
                 bar_stl(), filename="bar.stl")
    assert np.isfinite(r.fields.probes["displacement"]).all()


def test_a_facing_that_keeps_nothing_says_which_way_the_surface_in_its_region_faces():
    backwards = {**CLAMP, "facing": {"direction": [1, 0, 0], "max_angle_deg": 10}}  # the end face faces -x
    with pytest.raises(BoundaryError, match=r"clamp: none of the 1.4 m\^2 of surface in its region faces within 10 "
                                            r"degrees of \(1, 0, 0\); it faces mostly \(-1, 0, 0\)"):
        simulate(bar_job({"kind": "staggered"}, 0.5, [backwards]), bar_stl(), filename="bar.stl")


def test_python_api_functions_that_fail_are_errors_naming_the_boundary():
    job = bar_job({"kind": "staggered"}, 0.5, [CLAMP], gravity=(0, 0, 0))
    job["boundaries"].append({"kind": "traction", "name": "tip", "region": {"box": [[9.9, -2, -2], [11, 2, 2]]},
                              "value": [0, 0, -1]})
    cases = [
        (Functions(displacement={"clamp": lambda x: 1 / 0}),
         r"clamp: the displacement: the function raised ZeroDivisionError: division by zero"),
        (Functions(displacement={"clamp": lambda x: np.zeros(len(x))}),
         r"clamp: the displacement: the function returned shape \[\d+\] for \d+ points; expected \[\d+, 3\]"),
        (Functions(traction={"tip": lambda x: np.zeros((len(x), 2))}), r"tip: the traction: the function returned"),
        (Functions(regions={"clamp": lambda x: np.zeros((len(x), 3))}),
         r"clamp: the region: the function returned shape \[\d+, 3\] for \d+ points; expected \[\d+\] \(or one value"),
        (Functions(body_force=lambda x: np.zeros(len(x))), r"loads: the body force: the function returned"),
        (Functions(displacement={"clamp2": lambda x: 0 * x}),  # a typo: the function would never run
         r"functions.displacement: 'clamp2' names no displacement boundary of the spec \(those are: 'clamp'\)"),
        (Functions(traction={"clamp": lambda x: 0 * x}), r"functions.traction: 'clamp' names no traction boundary"),
    ]
    for functions, message in cases:
        with pytest.raises(BoundaryError, match=message):
            simulate(job, bar_stl(), filename="bar.stl", functions=functions)
    # DG read a transposed [3, N] displacement as [N, 3] and solved it (a silently wrong answer)
    with pytest.raises(BoundaryError, match=r"clamp: the displacement: the function returned shape \[3, \d+\]"):
        simulate({**job, "method": {"kind": "dg", "degree": 1}}, bar_stl(), filename="bar.stl",
                 functions=Functions(displacement={"clamp": lambda x: np.zeros((3, len(x)))}))
    for functions, message in [
        (Functions(regions={"clamp": lambda x: np.full(len(x), np.nan)}), r"clamp: the region's function returned NaN"),
        (Functions(traction={"tip": lambda x: np.full(x.shape, np.inf)}), r"tip: the traction is not finite"),
        (Functions(traction={"tip": lambda x: (1 + 1j) * x}), r"tip: the traction: the function raised TypeError: it "
                                                               r"returned complex numbers"),
    ]:
        with pytest.raises(BoundaryError, match=message):
            simulate(job, bar_stl(), filename="bar.stl", functions=functions)
    with pytest.raises(BoundaryError, match=r"functions.stress_form: 'divergence' or 'quadrature', got 'Divergence'"):
        Functions(stress_form="Divergence")  # it used to mean "quadrature"
    with pytest.raises(BoundaryError, match=r"functions: an engine.pipeline.Functions, got dict"):
        simulate(job, bar_stl(), filename="bar.stl", functions={"displacement": {}})


def test_a_constant_stress_in_the_divergence_form_loads_the_free_bar_exactly():
    sigma = np.array([[2.0, 0.5, 0.0], [0.5, -1.0, 0.0], [0.0, 0.0, 0.0]]) * 1e6  # it raised IndexError
    job = bar_job({"kind": "staggered"}, 0.5, [{"kind": "traction", "name": "all", "region": {"all": True},
                                                 "value": [0, 0, 0]}], gravity=(0, 0, 0), probes=[[5.0, 0.1, 0.2]])
    job["output"]["fields"] = ["displacement", "stress"]
    r = simulate(job, bar_stl(), filename="bar.stl", functions=Functions(stress={"all": lambda x: sigma}))
    voigt = r.fields.probes["stress"][0]  # xx, yy, zz, yz, xz, xy
    np.testing.assert_allclose(voigt, [2e6, -1e6, 0, 0, 0, 0.5e6], atol=1e-6 * 2e6)


def test_a_hold_over_most_of_the_surface_is_a_warning_that_names_the_half_space_rule():
    # the user meant x <= 0.1 but gave the normal that holds x >= 0.1: nearly the whole bar
    wrong = {**CLAMP, "region": {"halfspace": {"point": [0.1, 0, 0], "normal": [-1, 0, 0]}}}
    r = simulate(bar_job({"kind": "staggered"}, 0.5, [wrong]), bar_stl(), filename="bar.stl")
    (warning,) = [w for w in r.solver.warnings if w.startswith("clamp:")]
    assert "holds 97% of the surface" in warning and "the normal points out of it" in warning
    r = simulate(bar_job({"kind": "staggered"}, 0.5, [CLAMP]), bar_stl(), filename="bar.stl")
    assert not any(w.startswith("clamp:") for w in r.solver.warnings)


def test_a_solid_thin_for_its_grid_is_a_warning_only_there():
    thin = [w for w in simulate(bar_job({"kind": "staggered"}, 0.5, [CLAMP]), bar_stl(), filename="bar.stl").solver.warnings
            if "thin for this grid" in w]  # a 1 m bar, 2 cells across: 2V/A = 0.48 m, 0.95 cells
    assert len(thin) == 1 and "is 0.95 cells of h = 0.5 m" in thin[0] and "method.kind 'dg'" in thin[0]
    r = simulate(bar_job({"kind": "staggered"}, 0.25, [CLAMP]), bar_stl(), filename="bar.stl")
    assert not any("thin for this grid" in w for w in r.solver.warnings)  # 1.9 cells


def test_clamped_thick_sphere_converges_at_second_order():
    """:func:`clamped_sphere_error` at nu 0.3, measured 1.59e-2, 4.01e-3, 1.23e-3 at h = 1/10, 1/20,
    1/40 (fitted order 1.85); with the clamp holding the samples inside |x| > 0.98 it was 9.6e-2,
    1.1e-2, 2.7e-2."""
    errors = [clamped_sphere_error(0.3, h)[0] for h in (0.1, 0.05, 0.025)]
    assert errors[0] > errors[1] > errors[2], errors
    assert np.polyfit(np.log([0.1, 0.05, 0.025]), np.log(errors), 1)[0] >= 1.8, errors
    assert errors[2] < 1.5e-3, errors
