"""Problems with exact solutions, shared by the tests and the accuracy benchmark's methods (voxelastic and the peer).

Each :class:`Problem` says what the solid is, what is prescribed, the exact displacement and
stress, and the interior probe points where every method's error is measured. voxelastic runs
them through ``engine.simulate`` with :meth:`Problem.job`; the peer (``benchmarks.peer``) meshes
the same geometry with gmsh and applies the same conditions.

- ``lame``: thick sphere a = 0.5 < r < b = 1 m under internal pressure p = 1e4 Pa, E = 1e7 Pa,
  nu = 0.3, no displacement boundary (the pressure balances; rigid modes are removed).
  u = u_r(r) x / r, u_r = p a^3 / (E (b^3 - a^3)) ((1 - 2 nu) r + (1 + nu) b^3 / (2 r^2)).
- ``annulus``: 2D, plane strain, 0.325 < r < 0.8 m, mu = lambda = 1 (E = 2.5, nu = 0.25),
  u = (cos 2pi x cos 2pi y, sin 2pi x sin 2pi y) with its body force 8 pi^2 u (Dolny 2025 sec. 5.1);
  the exact u on the inner circle, the exact traction sigma n on the outer circle. Divergence-free.
- ``ball``: unit ball, E = 1, nu = 0.3, u = 0.01 (sin x cos y, sin y cos z, sin z cos x) with its
  body force, the exact u on the cap z <= -0.5 (``BALL_CAP``) and the exact traction sigma n on the
  rest of the surface. Exercises shear and lambda (div u != 0). Every method holds the cap's
  surface; the probes stay above it (z > -0.48), as when the staggered method held its volume.

The voxelastic geometry of the spheres is an icosphere (subdivisions 6: 81,920 triangles per sphere, facet centres up to 7e-5 of the radius inside it); the
exact solution of ``lame`` uses the radii of spheres with the facetted volumes, as the staggered
verification test does. The peer meshes the true spheres.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

PROBES = 1200
BALL_CAP = -0.5  # [m] the ball's displacement boundary is its surface below this z


@dataclass(frozen=True)
class Problem:
    """One benchmark problem; see the module docstring for the physics.

    exact(x [N, d]) -> u [N, d] [m]; stress(x) -> sigma [N, d, d] [Pa]; probes [PROBES, d] [m]
    lie at least 2% of the wall inside the solid.
    """

    name: str
    dim: int
    youngs_modulus: float
    poisson_ratio: float
    exact: Callable[[np.ndarray], np.ndarray]
    stress: Callable[[np.ndarray], np.ndarray]
    probes: np.ndarray
    body_force: Callable[[np.ndarray], np.ndarray] | None = None
    radii: tuple[float, ...] = field(default=())  # lame: (a, b); annulus: (inner, outer); ball: (r,)
    pressure: float = 0.0

    @property
    def lame(self) -> tuple[float, float]:
        E, nu = self.youngs_modulus, self.poisson_ratio
        return E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))

    def von_mises(self, x: np.ndarray) -> np.ndarray:
        """Exact von Mises stress [N] [Pa] at x (3D; 2D plane strain with sigma_zz = lambda tr eps)."""
        return von_mises_of(self.stress(x), self.lame[0] / (2 * (self.lame[0] + self.lame[1])))

    def surface_mesh(self):
        """The triangles voxelastic reads for this problem (trimesh; None for the 2D annulus's polygons)."""
        return {"lame": _shell, "ball": _ball_mesh}.get(self.name, lambda: None)()

    def job(self, method: dict, cell_size: float) -> tuple[dict, object, object]:
        """(spec dict, mesh (trimesh or None), engine.pipeline.Functions) for a voxelastic run."""
        from engine.pipeline import Functions

        material = {"youngs_modulus": self.youngs_modulus, "poisson_ratio": self.poisson_ratio}
        output = {"fields": ["displacement", "von_mises"], "probes": self.probes.tolist(), "surface": False}
        grid = {"cell_size": cell_size, "padding": 1}
        base = {"dimension": self.dim, "grid": grid, "method": method, "material": material, "output": output,
                "solver": {"rtol": 1e-10}}
        if self.name == "lame":
            a, b = self.radii
            spec = {**base, "geometry": {"mesh": "shell.stl"},
                    "boundaries": [{"kind": "pressure", "name": "inner", "value": self.pressure,
                                    "region": {"sphere": {"center": [0, 0, 0], "radius": 0.5 * (a + b)}}}]}
            return spec, self.surface_mesh(), Functions()
        if self.name == "annulus":
            inner, outer = self.radii
            middle = 0.5 * (inner + outer)
            spec = {**base, "geometry": {"polygon": [circle(outer), circle(inner)]},
                    "boundaries": [
                        {"kind": "displacement", "name": "inner", "value": [0, 0],
                         "region": {"sphere": {"center": [0, 0], "radius": middle}}},
                        {"kind": "traction", "name": "outer", "region": {"all": True}, "value": [0, 0]}]}
            outside = lambda x: np.hypot(x[:, 0], x[:, 1]) > middle  # noqa: E731
            return spec, None, Functions(body_force=self.body_force, displacement={"inner": self.exact},
                                         stress={"outer": self.stress}, regions={"outer": outside})
        spec = {**base, "geometry": {"mesh": "ball.stl"},
                "boundaries": [
                    {"kind": "displacement", "name": "cap", "value": [0, 0, 0],
                     "region": {"halfspace": {"point": [0, 0, BALL_CAP], "normal": [0, 0, 1]}}},
                    {"kind": "traction", "name": "rest", "value": [0, 0, 0],
                     "region": {"halfspace": {"point": [0, 0, BALL_CAP], "normal": [0, 0, -1]}}}]}
        return spec, self.surface_mesh(), Functions(body_force=self.body_force, displacement={"cap": self.exact},
                                             stress={"rest": self.stress})


def von_mises_of(sigma: np.ndarray, nu_plane: float = 0.0) -> np.ndarray:
    """Von Mises [N] of stresses [N, d, d]; 2D: plane strain, sigma_zz = nu (sigma_xx + sigma_yy)."""
    if sigma.shape[-1] == 2:
        s = np.zeros(sigma.shape[:-2] + (3, 3))
        s[..., :2, :2] = sigma
        s[..., 2, 2] = nu_plane * (sigma[..., 0, 0] + sigma[..., 1, 1])
        sigma = s
    dev = sigma - np.trace(sigma, axis1=-2, axis2=-1)[..., None, None] * np.eye(3) / 3
    return np.sqrt(1.5 * np.einsum("...ab,...ab->...", dev, dev))


def relative_l2(got: np.ndarray, exact: np.ndarray) -> float:
    """sqrt(sum |got - exact|^2 / sum |exact|^2) over probes; NaN rows (probe not located) count as errors."""
    diff = np.nan_to_num(np.asarray(got, float) - exact, nan=np.inf)
    return float(np.sqrt(np.sum(diff**2) / np.sum(np.asarray(exact) ** 2)))


# ----------------------------------------------------------------------------- geometry
@lru_cache(maxsize=None)
def _shell():
    import trimesh

    outer = trimesh.creation.icosphere(subdivisions=6, radius=1.0)
    inner = trimesh.creation.icosphere(subdivisions=6, radius=0.5)
    inner.invert()
    return trimesh.util.concatenate([outer, inner])


@lru_cache(maxsize=None)
def _ball_mesh():
    import trimesh

    return trimesh.creation.icosphere(subdivisions=6, radius=1.0)


def circle(radius: float, n: int = 4096) -> list[list[float]]:
    """n points [n, 2] on the circle of ``radius`` [m] about the origin, counter-clockwise (a polygon loop)."""
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.stack([radius * np.cos(t), radius * np.sin(t)], axis=1).tolist()


def _shell_probes(dim: int, inner: float, outer: float, seed: int) -> np.ndarray:
    """PROBES points uniform in volume in inner + 2% < r < outer - 2% of the wall."""
    gen = np.random.default_rng(seed)
    wall = outer - inner
    lo, hi = inner + 0.02 * wall, outer - 0.02 * wall
    d = gen.normal(size=(PROBES, dim))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = (lo**dim + gen.uniform(size=PROBES) * (hi**dim - lo**dim)) ** (1 / dim)
    return d * r[:, None]


# ----------------------------------------------------------------------------- problems
def _lame() -> Problem:
    a, b, p, E, nu = 0.5, 1.0, 1.0e4, 1.0e7, 0.3
    import trimesh

    # the facetted spheres' volume-equivalent radii (the peer meshes the true radii, see benchmarks/peer.py)
    a_eff = (3 * trimesh.creation.icosphere(subdivisions=6, radius=a).volume / (4 * np.pi)) ** (1 / 3)
    b_eff = (3 * trimesh.creation.icosphere(subdivisions=6, radius=b).volume / (4 * np.pi)) ** (1 / 3)
    return lame_problem(a_eff, b_eff, p, E, nu, probes=_shell_probes(3, a, b, 11))


def lame_problem(a: float, b: float, p: float, E: float, nu: float, probes: np.ndarray) -> Problem:
    """The Lamé thick sphere with radii a < b [m] (the peer passes the true radii)."""
    lam, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
    A = p * a**3 / ((b**3 - a**3) * (3 * lam + 2 * mu))  # u_r = A r + B / r^2
    B = p * a**3 * b**3 / ((b**3 - a**3) * 4 * mu)

    def exact(x):
        r = np.linalg.norm(x, axis=1)[:, None]
        return (A * r + B / r**2) * x / r

    def stress(x):
        # sigma = (3 lam + 2 mu) A I + 2 mu B / r^3 (I - 3 e e^T)
        r = np.linalg.norm(x, axis=1)
        e = x / r[:, None]
        eye = np.eye(3)[None]
        return (3 * lam + 2 * mu) * A * eye + (2 * mu * B / r**3)[:, None, None] * (eye - 3 * e[:, :, None] * e[:, None, :])

    return Problem("lame", 3, E, nu, exact, stress, probes, radii=(a, b), pressure=p)


ANNULUS_RADII = (0.325, 0.8)  # [m] inner, outer (Dolny 2025 sec. 5.1, in a domain of width 2)


def annulus_exact(x: np.ndarray) -> np.ndarray:
    """The annulus' u [N, 2] at x [N, 2]: (cos 2pi x cos 2pi y, sin 2pi x sin 2pi y) (divergence-free)."""
    two_pi = 2 * np.pi
    return np.stack([np.cos(two_pi * x[:, 0]) * np.cos(two_pi * x[:, 1]),
                     np.sin(two_pi * x[:, 0]) * np.sin(two_pi * x[:, 1])], axis=1)


def annulus_stress(x: np.ndarray) -> np.ndarray:
    """sigma [N, 2, 2] of the annulus (mu = lambda = 1): eps_xy = 0 and tr eps = 0, so sigma = 2 eps =
    diag(-1, 1) 4 pi sin 2pi x cos 2pi y."""
    two_pi = 2 * np.pi
    s = 2 * two_pi * np.sin(two_pi * x[:, 0]) * np.cos(two_pi * x[:, 1])
    out = np.zeros((len(x), 2, 2))
    out[:, 0, 0], out[:, 1, 1] = -s, s
    return out


def annulus_body_force(x: np.ndarray) -> np.ndarray:
    """b = -div sigma = 8 pi^2 u [N, 2] of the annulus (div u = 0, mu = 1)."""
    return 2 * (2 * np.pi) ** 2 * annulus_exact(x)


def _annulus() -> Problem:
    return Problem("annulus", 2, 2.5, 0.25, annulus_exact, annulus_stress, _shell_probes(2, *ANNULUS_RADII, 12),
                   body_force=annulus_body_force, radii=ANNULUS_RADII)


def _ball_problem() -> Problem:
    E, nu, amp = 1.0, 0.3, 0.01
    lam, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))

    def exact(x):
        X, Y, Z = x.T
        return amp * np.stack([np.sin(X) * np.cos(Y), np.sin(Y) * np.cos(Z), np.sin(Z) * np.cos(X)], axis=1)

    def gradient(x):  # du_p / dx_a at [:, p, a]
        X, Y, Z = x.T
        g = np.zeros((len(x), 3, 3))
        g[:, 0, 0], g[:, 0, 1] = np.cos(X) * np.cos(Y), -np.sin(X) * np.sin(Y)
        g[:, 1, 1], g[:, 1, 2] = np.cos(Y) * np.cos(Z), -np.sin(Y) * np.sin(Z)
        g[:, 2, 2], g[:, 2, 0] = np.cos(Z) * np.cos(X), -np.sin(Z) * np.sin(X)
        return amp * g

    def stress(x):
        g = gradient(x)
        eps = 0.5 * (g + g.transpose(0, 2, 1))
        return 2 * mu * eps + lam * np.trace(eps, axis1=1, axis2=2)[:, None, None] * np.eye(3)

    def body_force(x):
        X, Y, Z = x.T
        lap = -2 * np.stack([np.sin(X) * np.cos(Y), np.sin(Y) * np.cos(Z), np.sin(Z) * np.cos(X)], axis=1)
        grad_div = np.stack([-np.sin(X) * (np.cos(Y) + np.cos(Z)), -np.sin(Y) * (np.cos(X) + np.cos(Z)),
                             -np.sin(Z) * (np.cos(Y) + np.cos(X))], axis=1)
        return -amp * (mu * lap + (lam + mu) * grad_div)

    return Problem("ball", 3, E, nu, exact, stress, _ball_probes(13), body_force=body_force, radii=(1.0,))


def _ball_probes(seed: int) -> np.ndarray:
    """PROBES points uniform in volume in r < 0.98 above the cap (z > BALL_CAP + 0.02)."""
    gen = np.random.default_rng(seed)
    out = np.zeros((0, 3))
    while len(out) < PROBES:
        x = gen.uniform(-0.98, 0.98, size=(4 * PROBES, 3))
        keep = (np.linalg.norm(x, axis=1) < 0.98) & (x[:, 2] > BALL_CAP + 0.02)
        out = np.concatenate([out, x[keep]])
    return out[:PROBES]


@lru_cache(maxsize=None)
def problem(name: str) -> Problem:
    """The named problem: "lame", "annulus" or "ball"."""
    makers = {"lame": _lame, "annulus": _annulus, "ball": _ball_problem}
    if name not in makers:
        raise KeyError(f"problem: one of {sorted(makers)}, got {name!r}")
    return makers[name]()


def lame_at(nu: float) -> Problem:
    """The "lame" problem (same facetted shell, probes, pressure and E) at Poisson's ratio ``nu``."""
    base = problem("lame")
    return lame_problem(*base.radii, base.pressure, base.youngs_modulus, nu, base.probes)


def simulate_problem(pb: Problem, method: dict, cell_size: float, fields: list[str] | None = None):
    """``engine.simulate`` of :meth:`Problem.job` (a mesh goes through a temporary binary PLY, which
    keeps float64 vertices); ``fields``: the output fields when not the job's own. Returns the Result."""
    import tempfile
    from pathlib import Path

    from engine import simulate
    from engine.geometry.cache import GeometryCache

    spec, mesh, functions = pb.job(method, cell_size)
    if fields is not None:
        spec["output"]["fields"] = list(fields)
    with tempfile.TemporaryDirectory() as tmp:
        path = None
        if mesh is not None:
            path = Path(tmp) / "solid.ply"
            spec["geometry"]["mesh"] = path.name
            mesh.export(path)
        return simulate(spec, path, cache=GeometryCache(None), functions=functions)
