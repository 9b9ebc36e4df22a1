"""The holed plates of issue 19: stress at a hole's edge, compared with a converged P2 reference.

One part, two loadings. The part: a plate of ``SIZE`` = 1 x 1 x 0.2 m (corner at the origin) with
a cylindrical through hole of radius ``RADIUS`` = 0.15 m along z at its centre (0.5, 0.5); E =
1e7 Pa, nu = 0.3. Its surface is a manifold3d boolean (:func:`verification.parts.holed_plate`) with
``SECTIONS`` = 256 facets around the hole, a vertex at every quarter turn, vertices snapped to the
exact planes and circle (:func:`plate_mesh`); the reference (``benchmarks.plate_peer``) meshes the
true cylinder, whose distance from the facets is R (1 - cos(pi / 256)) = 1.1e-5 m.

- ``tension``: traction +-``LOAD`` e_x on the end faces x = 1 and x = 0, nothing held (a balanced
  free body: the methods solve off the rigid modes). Quantity: sigma_xx / LOAD at the hole's edge
  on the mid-plane, (0.5, 0.65, 0.1), where the hoop stress peaks (the stress concentration factor
  on the gross section; 3.1 for this d / W = 0.3, by the reference).
- ``bending``: pressure ``LOAD`` on the top face z = 0.2, the end faces x = 0 and x = 1 clamped (a
  wide clamped-clamped beam with the hole at mid-span). Quantity: sigma_xx / LOAD where the loaded
  face meets the hole, (0.5, 0.65, 0.2): both faces there fix every other component (sigma_yy =
  sigma_xy = sigma_yz = sigma_xz = 0, sigma_zz = -LOAD), so sigma_xx is the one the method computes.

Both points lie on the surface and on the plate's x and y symmetry planes (the methods' grids are
symmetric about them when 0.5 / h is an integer or a half-integer). Each method reads the
quantity from ``output.probes``: :data:`INSET` [m] inside along the hole's normal (-e_y), so that a
probe is in material for either method whatever the cell lookup does on the surface itself; the
P2 reference is evaluated at the surface point (the mean over the elements holding it), whose
stress differs from the probe's by O(INSET / R) = 7e-8 relative.

The reference values, their mesh sizes and the command that made them are in ``REFERENCE_FILE``
(written by ``python -m benchmarks.plate_peer --write``); tests and the benchmark read it here, so
neither needs scikit-fem.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

SIZE = (1.0, 1.0, 0.2)  # [m] plate extents along x, y, z
RADIUS = 0.15  # [m] hole radius, axis along z through (0.5, 0.5)
CENTRE = (0.5, 0.5)  # [m] hole axis in the x-y plane
SECTIONS = 256  # facets around the hole in the voxelastic geometry
E, NU = 1.0e7, 0.3  # [Pa], [-]
LOAD = 1.0e4  # [Pa] end traction (tension) or top pressure (bending)
INSET = 1.0e-8  # [m] probes sit this far inside the hole's surface
FACE_SLACK = 1e-9  # [m] boundary regions reach this far past their face (inside: the face alone)
FACING = 30.0  # [degrees] largest angle between a boundary's facets and its face normal
REFERENCE_FILE = Path(__file__).with_name("plate_reference.json")
CASES = ("tension", "bending")


@dataclass(frozen=True)
class PlateCase:
    """One loading of the holed plate: ``point`` [3] [m] on the surface where sigma_xx / LOAD is read."""

    name: str
    point: tuple[float, float, float]

    @property
    def probe(self) -> np.ndarray:
        """The point moved INSET inside the material [3] [m] (the hole's outward normal there is -e_y)."""
        return np.asarray(self.point) + np.array([0.0, INSET, 0.0])

    def boundaries(self) -> list[dict]:
        """The job spec's ``boundaries`` (faces picked by half-spaces reaching FACE_SLACK past them
        and by ``facing``)."""
        L, _, T = SIZE
        if self.name == "tension":
            return [_on_face("traction", "right", 0, L, [LOAD, 0, 0]), _on_face("traction", "left", 0, 0.0, [-LOAD, 0, 0])]
        return [_on_face("pressure", "top", 2, T, LOAD), _on_face("displacement", "clamp_right", 0, L, [0, 0, 0]),
                _on_face("displacement", "clamp_left", 0, 0.0, [0, 0, 0])]

    def job(self, method: dict, h: float, mesh_name: str = "plate.ply", surface: bool = False) -> dict:
        """The job spec (a dict, ``voxelastic run``'s JSON) on cells of ``h`` [m]: stress and von Mises
        at the probe, the surface only when ``surface``."""
        return {"dimension": 3, "geometry": {"mesh": mesh_name}, "grid": {"cell_size": h, "padding": 1},
                "method": method, "material": {"youngs_modulus": E, "poisson_ratio": NU},
                "boundaries": self.boundaries(), "solver": {"rtol": 1e-10, "arch": "cpu"},
                "output": {"fields": ["stress", "von_mises"], "probes": [self.probe.tolist()], "surface": surface}}

    def reference(self) -> float:
        """The converged P2 reference of sigma_xx / LOAD at the probe (REFERENCE_FILE)."""
        return float(reference_table()[self.name]["value"])


def _on_face(kind: str, name: str, axis: int, at: float, value) -> dict:
    """A boundary on the plate's face ``axis`` = ``at`` [m] (an outer face: outward normal +-e_axis)."""
    side = 1.0 if at > 0 else -1.0
    normal = [0.0, 0.0, 0.0]
    normal[axis] = -side  # the half-space beyond (at - side * FACE_SLACK), towards the face's outside
    point = [0.0, 0.0, 0.0]
    point[axis] = at - side * FACE_SLACK
    facing = [0.0, 0.0, 0.0]
    facing[axis] = side
    return {"kind": kind, "name": name, "value": value, "region": {"halfspace": {"point": point, "normal": normal}},
            "facing": {"direction": facing, "max_angle_deg": FACING}}


PLATES = {"tension": PlateCase("tension", (0.5, CENTRE[1] + RADIUS, SIZE[2] / 2)),
          "bending": PlateCase("bending", (0.5, CENTRE[1] + RADIUS, SIZE[2]))}


@lru_cache(maxsize=None)
def plate_mesh():
    """The plate's closed surface (trimesh): the manifold3d boolean, its vertices snapped to the
    exact faces (within 1e-6 m) and the hole's to the circle of RADIUS (manifold3d rounds them to
    ~3e-8 m)."""
    from verification.parts import holed_plate

    mesh = holed_plate(SIZE, RADIUS, SECTIONS)
    v = np.array(mesh.vertices, dtype=float)
    for axis, extent in enumerate(SIZE):
        for plane in (0.0, extent):
            v[np.abs(v[:, axis] - plane) < 1e-6, axis] = plane
    d = v[:, :2] - np.asarray(CENTRE)
    r = np.hypot(d[:, 0], d[:, 1])
    on_hole = np.abs(r - RADIUS) < 1e-6
    v[on_hole, :2] = np.asarray(CENTRE) + d[on_hole] * (RADIUS / r[on_hole])[:, None]
    mesh.vertices = v
    return mesh


def sigma_xx(stress_voigt: np.ndarray) -> float:
    """sigma_xx / LOAD of the first probe's Voigt stress [n, 6] (xx, yy, zz, yz, xz, xy) [Pa]."""
    return float(np.asarray(stress_voigt)[0, 0]) / LOAD


@lru_cache(maxsize=None)
def reference_table() -> dict:
    """REFERENCE_FILE's content: per case its value and the refinement study behind it."""
    return json.loads(REFERENCE_FILE.read_text())


def run_plate(case: PlateCase, method: dict, h: float, directory: Path, surface: bool = False) -> tuple[float, object]:
    """Run the case through ``voxelastic run`` (engine.cli.main, in this process) in ``directory``:
    writes plate.ply and job.json there, reads the result back. Returns (sigma_xx / LOAD at the
    probe, the engine.output result)."""
    from engine.cli import main
    from engine.output import read_result

    directory = Path(directory)
    plate_mesh().export(directory / "plate.ply")  # binary PLY: float64 vertices
    (directory / "job.json").write_text(json.dumps(case.job(method, h, surface=surface)))
    out = directory / "result.h5"
    rc = main(["run", str(directory / "job.json"), "-o", str(out), "--no-cache"])
    if rc != 0:
        raise RuntimeError(f"voxelastic run failed with status {rc} ({case.name}, {method}, h = {h})")
    result = read_result(out)
    return sigma_xx(result.fields.probes["stress"]), result
