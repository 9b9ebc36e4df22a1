"""The solids of the stress suite and the cut-cell tests, with their closed-form answers.

The cantilever of most stress cases is a 1 m bar, 0.25 m square, E = 1 MPa, nu = 0.3, clamped at
its near end face and loaded by a traction on its far one (:class:`Bar`, :func:`cantilever`);
:func:`timoshenko_tip` and :func:`elastica_tip` are the beam-theory tips it is compared with.
:func:`hollow_box` (thin walls) and :func:`holed_plate` (genus 1) are the other shapes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import trimesh

if TYPE_CHECKING:
    from engine.grid import Grid

# The cantilever of most cases: 1 m long, 0.25 m square, E = 1 MPa, clamped at x = 0.
LENGTH, WIDTH = 1.0, 0.25
LONG = 2.0  # the rotated bar and the free body: aspect ratio 8
E0, NU0, RHO = 1.0e6, 0.3, 1000.0
TIP_TRACTION = 1.0e2  # [Pa] on the end face: tip deflection ~6e-3 m, bending strain <= 2.4e-3
OFFSETS = (0.0, 1e-6, 1e-4, 1e-2, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.99, 1 - 1e-4, 1 - 1e-6)


@dataclass(frozen=True)
class Bar:
    """A square bar of ``length`` x ``width`` x ``width`` [m]. ``frame`` [3, 3] rows: the axis, the
    load direction, the third direction (right-handed); ``origin`` [3]: centre of the end face
    at axial coordinate 0 [m]."""

    length: float
    width: float
    frame: np.ndarray
    origin: np.ndarray

    def mesh(self) -> trimesh.Trimesh:
        """The bar's closed surface (12 triangles) in place."""
        w = self.width / 2
        box = trimesh.creation.box(bounds=[[0.0, -w, -w], [self.length, w, w]])
        m = np.eye(4)
        m[:3, :3] = self.frame.T  # columns: where e_x, e_y, e_z of the box go
        m[:3, 3] = self.origin
        box.apply_transform(m)
        return box

    def point(self, axial: float, lateral: float = 0.0) -> list[float]:
        """Position [3] at ``axial`` along the axis, ``lateral`` along the load direction [m]."""
        return (self.origin + axial * self.frame[0] + lateral * self.frame[1]).tolist()

    def beyond(self, axial: float, side: int) -> dict:
        """Spec region: the half-space of axial coordinate <= axial (side -1) or >= axial (+1)."""
        normal = (self.frame[0] if side < 0 else -self.frame[0]).tolist()
        return {"halfspace": {"point": self.point(axial), "normal": normal}}

    def end(self, side: int, slack: float) -> dict:
        """Spec region of the far (side +1) or near (-1) end face, reaching ``slack`` [m] past it."""
        return self.beyond(self.length - slack, +1) if side > 0 else self.beyond(slack, -1)

    def direction(self, k: int, scale: float) -> list[float]:
        """Vector [3]: ``scale`` along frame row k (0 axis, 1 load direction, 2 third)."""
        return (scale * self.frame[k]).tolist()


ALIGNED = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])  # axis x, load along z
# A generic orientation: 0.5 rad about (1, 2, 3), the DG tests' rotated box.
ROTATION = trimesh.transformations.rotation_matrix(0.5, [1, 2, 3])[:3, :3]
ROTATED = ALIGNED @ ROTATION.T  # each row rotated


def cantilever(length: float = LENGTH, frame: np.ndarray = ALIGNED, origin=(0.0, 0.0, 0.0)) -> Bar:
    """The suite's W x W bar of ``length`` [m] in ``frame``, end face centred at ``origin`` [m]."""
    return Bar(length, WIDTH, np.asarray(frame, dtype=float), np.asarray(origin, dtype=float))


def offset_grid(bar_cells: tuple[int, int, int], h: float) -> Grid:
    """Pinned grid (spacing h [m]) holding the bar, whose corner sits at offset * h * (1, 0.6, 0.3)
    with offset in [0, 1): origin at -h, one padding cell plus one for the offset per axis."""
    from engine.grid import Grid

    return Grid(origin=(-h, -h, -h), spacing=h, shape=tuple(n + 3 for n in bar_cells))


def offset_bar(offset: float, h: float) -> Bar:
    """The cantilever with its corner at offset * h * (1, 0.6, 0.3) [m]."""
    return cantilever(origin=np.array([0.0, WIDTH / 2, WIDTH / 2]) + offset * h * np.array([1.0, 0.6, 0.3]))


def hollow_box(outer: tuple[float, float, float], wall: float) -> trimesh.Trimesh:
    """Closed box of ``outer`` extents [m] (corner at 0) with a sealed cavity: walls ``wall`` [m]."""
    out = trimesh.creation.box(bounds=[[0, 0, 0], list(outer)])
    cavity = trimesh.creation.box(bounds=[[wall] * 3, [o - wall for o in outer]])
    cavity.invert()
    return trimesh.util.concatenate([out, cavity])


def holed_plate(size: tuple[float, float, float], radius: float, sections: int = 48) -> trimesh.Trimesh:
    """Plate of ``size`` [m] (corner at 0) with a cylindrical through hole of ``radius`` [m] along z
    at its centre (manifold3d boolean; ``sections`` facets around, a vertex at angle 0 from +x)."""
    plate = trimesh.creation.box(bounds=[[0, 0, 0], list(size)])
    drill = trimesh.creation.cylinder(radius=radius, height=3 * size[2], sections=sections)
    drill.apply_translation([size[0] / 2, size[1] / 2, size[2] / 2])
    holed = plate.difference(drill, engine="manifold")
    if not holed.is_watertight or holed.euler_number != 0:
        raise RuntimeError(f"holed plate: boolean gave watertight={holed.is_watertight}, "
                           f"Euler number {holed.euler_number} (want 0: one through hole)")
    return holed


# ----------------------------------------------------------------------------- beam theory


def timoshenko_tip(force: float, length: float, width: float, youngs: float, nu: float) -> float:
    """Tip deflection [m] of a square cantilever under an end force [N]: bending P L^3 / (3 E I) plus
    shear P L / (k G A), k = 10 (1 + nu) / (12 + 11 nu) (Cowper's rectangle)."""
    inertia, area = width**4 / 12, width**2
    shear = youngs / (2 * (1 + nu))
    k = 10 * (1 + nu) / (12 + 11 * nu)
    return force * length**3 / (3 * youngs * inertia) + force * length / (k * shear * area)


def elastica_tip(load: float) -> float:
    """Tip deflection / length of an inextensible cantilever under a dead end load, transverse to the
    undeformed axis, with load = P L^2 / (E I): theta'' = -load cos(theta), theta(0) = 0,
    theta'(1) = 0, deflection = int_0^1 sin(theta) ds (shooting on theta(1))."""
    from scipy.integrate import solve_ivp
    from scipy.optimize import brentq

    def shoot(tip_angle: float) -> tuple[float, float]:
        # integrate from the free end back: theta(1) = tip_angle, theta'(1) = 0
        sol = solve_ivp(lambda s, y: [y[1], -load * np.cos(y[0]), np.sin(y[0])], (1.0, 0.0),
                        [tip_angle, 0.0, 0.0], rtol=1e-11, atol=1e-13)
        return sol.y[0, -1], -sol.y[2, -1]

    angle = brentq(lambda a: shoot(a)[0], 1e-9, np.pi / 2 - 1e-9, xtol=1e-13)
    return shoot(angle)[1]
