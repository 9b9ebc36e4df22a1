"""Bodies held on curved surfaces, with exact solutions (issues 17 and 21): the thick sphere clamped
on its outer surface, its 2D twin the annulus, and the sphere clamped below a height (a patch with a
rim, no closed form: compared with a reference run).

Each confined body's displacement is O(1 / lambda), so near nu = 1/2 a hold that locks shows at
full size. Errors are relative L2 norms of u at interior probes.
"""

from __future__ import annotations

import numpy as np
import trimesh

A_IN, B_OUT = 0.5, 1.0  # radii [m]
CLAMP_RADIUS = 0.98  # the clamp's region: |x| > this (every point of the outer surface, none of the inner)


def lame(nu: float) -> tuple[float, float]:
    """(lambda, mu) [Pa] for E = 1 Pa."""
    return nu / ((1 + nu) * (1 - 2 * nu)), 1 / (2 * (1 + nu))


def shell_stl(subdivisions: int = 5) -> bytes:
    """The thick sphere a < r < b as icospheres (outer outward, inner inverted), binary STL."""
    outer = trimesh.creation.icosphere(subdivisions=subdivisions, radius=B_OUT)
    inner = trimesh.creation.icosphere(subdivisions=subdivisions, radius=A_IN)
    inner.invert()
    return trimesh.util.concatenate([outer, inner]).export(file_type="stl")


def sphere_probes(d: int, count: int) -> np.ndarray:
    """``count`` points [count, d] in 0.55 < r < 0.95 (a fixed random set)."""
    x = np.random.default_rng(3).uniform(-1, 1, (20000, d))
    r = np.linalg.norm(x, axis=1)
    return x[(r > 0.55) & (r < 0.95)][:count]


def _job(d: int, h: float, nu: float, method: dict | None, probes: np.ndarray, geometry: dict) -> dict:
    return {"dimension": d, "geometry": geometry, "grid": {"cell_size": h, "padding": 1},
            "method": method or {"kind": "staggered"}, "material": {"youngs_modulus": 1.0, "poisson_ratio": nu},
            "boundaries": [{"kind": "pressure", "name": "inner", "value": 1.0,
                            "region": {"sphere": {"center": [0.0] * d, "radius": 0.75}}},
                           {"kind": "displacement", "name": "clamp", "value": [0.0] * d, "region": {"all": True}}],
            "solver": {"rtol": 1e-10}, "output": {"fields": ["displacement"], "probes": probes.tolist(), "surface": False}}


def _error(u: np.ndarray, exact: np.ndarray) -> float:
    return float(np.sqrt(np.sum((u - exact) ** 2) / np.sum(exact**2)))


def clamped_sphere_error(nu: float, h: float, method: dict | None = None) -> tuple[float, list[str]]:
    """Thick sphere a = 0.5, b = 1 (E = 1), pressure 1 inside, the outer surface held (u = 0 on the
    surface where |x| > 0.98): u = (A r + B / r^2) e_r, A = -B, B = 1 / ((3 lambda + 2 mu) + 4 mu / a^3).
    Relative L2 error at 500 probes in 0.55 < r < 0.95 at cell size ``h``, and the job's warnings."""
    lam, mu = lame(nu)
    B = 1.0 / ((3 * lam + 2 * mu) + 4 * mu / A_IN**3)
    probes = sphere_probes(3, 500)
    rp = np.linalg.norm(probes, axis=1)
    exact = ((-B * rp + B / rp**2) / rp)[:, None] * probes
    result = held_sphere(nu, h, method)
    return _error(result.fields.probes["displacement"], exact), result.solver.warnings


def clamped_sphere_pressure_error(nu: float, h: float, method: dict | None = None) -> tuple[float, float]:
    """The pressure of :func:`clamped_sphere_error`'s sphere against its exact one, the constant
    p = (3 lambda + 2 mu) B [Pa] (tr(eps) = 3 A everywhere): the relative L2 error at the 500 probes and
    the largest relative error over the cells that hold material."""
    lam, mu = lame(nu)
    B = 1.0 / ((3 * lam + 2 * mu) + 4 * mu / A_IN**3)
    exact = (3 * lam + 2 * mu) * B
    result = held_sphere(nu, h, method, fields=("pressure",))
    probes, cells = result.fields.probes["pressure"], result.fields.cells["pressure"]
    return (float(np.sqrt(np.mean((probes - exact) ** 2))) / exact,
            float(np.nanmax(np.abs(cells - exact))) / exact)


def rim_pressure_spikes(nu: float, h: float, method: dict | None = None, below: float = 0.3) -> float:
    """The sphere clamped below z = ``below`` (no closed form): the largest difference of a cell's pressure
    from the median of its 3^3 block's, over the 90th percentile of |p| (a smooth field gives well under 1)."""
    import warnings

    from scipy.ndimage import generic_filter

    cells = held_sphere(nu, h, method, below, fields=("pressure",)).fields.cells["pressure"]
    with warnings.catch_warnings():  # blocks outside the solid have no median
        warnings.simplefilter("ignore", RuntimeWarning)
        median = generic_filter(cells, np.nanmedian, size=3, mode="constant", cval=np.nan)
    solid = np.isfinite(cells)
    return float(np.abs(cells - median)[solid].max() / np.percentile(np.abs(cells[solid]), 90))


def clamped_annulus_error(nu: float, h: float) -> tuple[float, list[str]]:
    """The 2D (plane strain) twin of :func:`clamped_sphere_error`: the annulus a = 0.5 < r < 1 (polygons
    of 1,024 vertices), pressure 1 inside, clamped where |x| > 0.98; u_r = A r + B / r, A = -B,
    B = 1 / (2 (lambda + mu) + 8 mu). Relative L2 error at 400 probes in 0.55 < r < 0.95."""
    from engine import simulate
    from engine.pipeline import Functions

    lam, mu = lame(nu)
    B = 1.0 / (2 * (lam + mu) + 8 * mu)
    t = np.linspace(0, 2 * np.pi, 1025)[:-1]
    loops = [np.stack([r * np.cos(t), r * np.sin(t)], 1).tolist() for r in (B_OUT, A_IN)]
    probes = sphere_probes(2, 400)
    rp = np.linalg.norm(probes, axis=1)
    exact = ((-B * rp + B / rp) / rp)[:, None] * probes
    spec = _job(2, h, nu, None, probes, {"polygon": loops})
    result = simulate(spec, functions=Functions(regions={"clamp": lambda p: np.linalg.norm(p, axis=1) > CLAMP_RADIUS}))
    return _error(result.fields.probes["displacement"], exact), result.solver.warnings


def partly_clamped_sphere(nu: float, h: float, method: dict | None = None, below: float = 0.3,
                          subdivisions: int = 5) -> tuple[np.ndarray, list[str]]:
    """The sphere of :func:`clamped_sphere_error` clamped only where z < ``below`` [m] (the patch has a
    rim): the displacement [500, 3] [m] at its probes and the job's warnings."""
    result = held_sphere(nu, h, method, below, subdivisions)
    return result.fields.probes["displacement"], result.solver.warnings


def held_sphere(nu: float, h: float, method: dict | None = None, below: float = np.inf, subdivisions: int = 5,
                rtol: float = 1e-10, fields: tuple[str, ...] = ("displacement",)):
    """The engine's result for the thick sphere of :func:`clamped_sphere_error` clamped where |x| >
    CLAMP_RADIUS and z < ``below`` [m], at cell size ``h`` [m], probes at its 500 points."""
    from engine import simulate
    from engine.pipeline import Functions

    spec = _job(3, h, nu, method, sphere_probes(3, 500), {"mesh": "s.stl"})
    spec["solver"]["rtol"] = rtol
    spec["output"]["fields"] = list(fields)
    fn = Functions(regions={"clamp": lambda p: (np.linalg.norm(p, axis=1) > CLAMP_RADIUS) & (p[:, 2] < below)})
    return simulate(spec, shell_stl(subdivisions), filename="s.stl", functions=fn)


def difference(u: np.ndarray, reference: np.ndarray) -> float:
    """Relative L2 difference of probe displacements [n, d] from a reference's."""
    return _error(u, reference)
