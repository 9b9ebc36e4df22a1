"""The 2D annulus manufactured solution of Dolny (2025) section 5.1 on the staggered method (the
solution itself: :mod:`verification.problems`, shared with the accuracy benchmark).

mu = lambda = 1, u = (cos 2pi x cos 2pi y, sin 2pi x sin 2pi y) (divergence-free), so the body force
is b = -div sigma = 8 pi^2 u. Radii 0.325 / 0.8 in a domain of width 2 (h = 2 / N).

Errors: see :func:`errors` (at cell centres like the thesis, and at the staggered samples).
"""

from __future__ import annotations

import numpy as np

from engine.geometry.cache import GeometryCache
from engine.pipeline import Functions
from verification.problems import ANNULUS_RADII, circle
from verification.problems import annulus_body_force as body_force
from verification.problems import annulus_exact as exact
from verification.problems import annulus_stress as exact_stress

INNER, OUTER = ANNULUS_RADII


def material() -> dict:
    # E and nu with lambda = mu = 1: nu = 1/4, E = 2 mu (1 + nu) = 2.5
    return {"youngs_modulus": 2.5, "poisson_ratio": 0.25}


def annulus() -> list:
    """The annulus as a polygon: the outer circle and the inner one as a hole."""
    return [circle(OUTER), circle(INNER)]  # a point is solid inside an odd number of loops


def dirichlet_spec(n: int) -> dict:
    """The annulus with the exact displacement held on both circles (the thesis' all-Dirichlet
    problem; the thesis prescribes every sample outside the annulus, here the surface is held)."""
    return {
        "dimension": 2,
        "geometry": {"polygon": annulus()},
        "grid": {"cell_size": 2.0 / n, "padding": 1},
        "material": material(),
        "boundaries": [{"kind": "displacement", "name": "both", "region": {"all": True}, "value": [0, 0]}],
        "solver": {"rtol": 1e-11},
        "output": {"fields": ["displacement"], "surface": False},
    }


def traction_spec(n: int) -> dict:
    """The annulus with the exact displacement held on the inner circle and the exact traction
    sigma n on the outer one."""
    middle = 0.5 * (INNER + OUTER)
    return {
        "dimension": 2,
        "geometry": {"polygon": annulus()},
        "grid": {"cell_size": 2.0 / n, "padding": 1},
        "material": material(),
        "boundaries": [
            {"kind": "displacement", "name": "inner", "region": {"sphere": {"center": [0, 0], "radius": middle}},
             "value": [0, 0]},
            {"kind": "traction", "name": "outer", "region": {"all": True}, "value": [0, 0]},
        ],
        "solver": {"rtol": 1e-11},
        "output": {"fields": ["displacement"], "surface": False},
    }


def solve(kind: str, n: int, form: str = "quadrature"):
    """(method, state) of one problem at resolution n (N cells across the width-2 domain)."""
    from engine.pipeline import prepare_geometry
    from engine.staggered.problem import make_staggered
    from schemas import parse_job
    from engine.runtime import init

    init("cpu", "f64")
    if kind == "dirichlet":
        spec = parse_job(dirichlet_spec(n))
        fn = Functions(body_force=body_force, displacement={"both": exact})
    else:
        spec = parse_job(traction_spec(n))
        middle = 0.5 * (INNER + OUTER)
        fn = Functions(body_force=body_force, displacement={"inner": exact}, stress={"outer": exact_stress},
                       stress_form=form, regions={"outer": lambda x: np.hypot(x[:, 0], x[:, 1]) > middle})
    geo = prepare_geometry(spec, cache=GeometryCache(None))
    method = make_staggered(spec, geo, fn)
    return method, method.solve()


def errors(kind: str, n: int, form: str = "quadrature") -> dict:
    """Errors at resolution n; ``form``: how the traction becomes loads.

    "cells": (L1, L_inf) of the cell-centre displacement (the result's field: the mean of each
    cell's two face samples) as a vector norm, over cells whose centre lies in the annulus; L1 =
    h^2 sum |e| (the thesis' Table 5.2 matches this measure); "interior": the same over the cells at
    least 2h from both circles. "samples": (L1, L_inf) of each
    component at its own free samples inside the annulus, L1 = h^2 sum |e|. "iterations": CG.
    """
    method, state = solve(kind, n, form)
    h = method.grid.spacing
    a, p, x = method.dof_comp, method.dof_pos, method.sample_points()
    r = np.hypot(x[:, 0], x[:, 1])
    free = method.level.free[a, p] & (r > INNER) & (r < OUTER)
    e = np.abs(state.u[a[free], p[free]] - exact(x[free])[np.arange(int(free.sum())), a[free]])
    disp = method.cell_fields(state.u, ["displacement"])["displacement"].reshape(-1, 2)
    g = method.grid
    xc = np.stack(np.meshgrid(*[g.axis_coordinates(k) for k in range(2)], indexing="ij"), -1).reshape(-1, 2)
    rc = np.hypot(xc[:, 0], xc[:, 1])
    inside = (rc > INNER) & (rc < OUTER)
    ec = np.linalg.norm(disp[inside] - exact(xc[inside]), axis=1)
    deep = (rc[inside] > INNER + 2 * h) & (rc[inside] < OUTER - 2 * h)
    return {
        "cells": (float(h**2 * ec.sum()), float(ec.max())),
        "interior": (float(h**2 * ec[deep].sum()), float(ec[deep].max())),
        "samples": (float(h**2 * e.sum()), float(e.max())),
        "iterations": state.stats.iterations,
    }


def order(ns, values) -> float:
    return float(-np.polyfit(np.log(ns), np.log(values), 1)[0])
