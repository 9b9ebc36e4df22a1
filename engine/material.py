"""Linear isotropic elasticity as small pure functions (numpy; kernels get their own ti.func twin).

Voigt order follows the result contract: 3D (xx, yy, zz, yz, xz, xy), 2D (xx, yy, xy). Strains are
tensor components (epsilon_xy, not the engineering shear 2 epsilon_xy). 2D is plane strain:
epsilon_zz = 0, so sigma_zz = lambda tr(epsilon) enters the von Mises stress.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# The output fields that come from the strain: computed together where any is asked for
STRESS_FIELDS = ("strain", "stress", "von_mises", "pressure")


def lame_parameters(youngs_modulus: float, poisson_ratio: float) -> tuple[float, float]:
    """(lambda, mu) [Pa] from E [Pa] and nu [-] (0 <= nu < 0.5)."""
    E, nu = float(youngs_modulus), float(poisson_ratio)
    return E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))


@dataclass(frozen=True)
class Material:
    """E [Pa], nu [-], density [kg/m^3], model "linear" | "corotated"."""

    youngs_modulus: float
    poisson_ratio: float
    density: float = 1000.0
    model: str = "linear"

    @classmethod
    def from_spec(cls, spec) -> "Material":
        return cls(spec.youngs_modulus, spec.poisson_ratio, spec.density, spec.model)

    @property
    def lame(self) -> tuple[float, float]:
        return lame_parameters(self.youngs_modulus, self.poisson_ratio)


def _shear_slice(dim: int) -> slice:
    return slice(3, 6) if dim == 3 else slice(2, 3)


def stress(strain: np.ndarray, lam: float, mu: float, dim: int) -> np.ndarray:
    """sigma = lambda tr(eps) I + 2 mu eps, Voigt [..., 6 | 3] -> [..., 6 | 3] [Pa]."""
    strain = np.asarray(strain, dtype=float)
    out = 2 * mu * strain
    out[..., :dim] += lam * strain[..., :dim].sum(axis=-1, keepdims=True)
    return out


def normal_stresses(sigma: np.ndarray, dim: int, lam: float | None = None, mu: float | None = None) -> np.ndarray:
    """The three normal stresses [..., 3] [Pa] of Voigt stresses [..., 6 | 3]. 2D is plane strain:
    sigma_zz = nu (sigma_xx + sigma_yy) = lambda / (2 (lambda + mu)) (sxx + syy), hence ``lam``
    and ``mu``."""
    sigma = np.asarray(sigma, dtype=float)
    if dim == 3:
        return sigma[..., :3]
    if lam is None or mu is None:
        raise ValueError("plane strain needs lam and mu for sigma_zz")
    szz = lam / (2 * (lam + mu)) * (sigma[..., 0] + sigma[..., 1])
    return np.concatenate([sigma[..., :2], szz[..., None]], axis=-1)


def von_mises(sigma: np.ndarray, dim: int, lam: float | None = None, mu: float | None = None) -> np.ndarray:
    """von Mises stress [...] [Pa] of Voigt stresses [..., 6 | 3] (2D: plane strain, see
    :func:`normal_stresses`)."""
    normal = normal_stresses(sigma, dim, lam, mu)
    dev = normal - normal.mean(axis=-1, keepdims=True)
    shear = np.asarray(sigma, dtype=float)[..., _shear_slice(dim)]
    return np.sqrt(1.5 * (dev**2).sum(axis=-1) + 3 * (shear**2).sum(axis=-1))


def pressure(sigma: np.ndarray, dim: int, lam: float | None = None, mu: float | None = None) -> np.ndarray:
    """Pressure p = -tr(sigma) / 3 [...] [Pa] of Voigt stresses [..., 6 | 3], positive in
    compression (2D: plane strain's sigma_zz included, see :func:`normal_stresses`)."""
    return -normal_stresses(sigma, dim, lam, mu).mean(axis=-1)


def strain_fields(strain: np.ndarray, names: list[str] | tuple[str, ...], lam: float, mu: float, dim: int) -> dict[str, np.ndarray]:
    """The requested ones of STRESS_FIELDS from Voigt strains [..., 6 | 3]: "strain" itself,
    "stress" [..., 6 | 3] [Pa], "von_mises" and "pressure" [...] [Pa] (NaN strains stay NaN)."""
    out: dict[str, np.ndarray] = {}
    if "strain" in names:
        out["strain"] = strain
    if any(n in names for n in STRESS_FIELDS[1:]):
        sigma = stress(strain, lam, mu, dim)
        if "stress" in names:
            out["stress"] = sigma
        for name, of in (("von_mises", von_mises), ("pressure", pressure)):
            if name in names:
                out[name] = of(sigma, dim, lam, mu)
    return out
