"""CG iterations of held bodies other than the shell at nu 0.3 and 0.4999 (rtol 1e-8, the V-cycle),
and the held shell of ``benchmarks.staggered`` in other analyses and at other nu (rtol 1e-6).

    PYTHONPATH=. .venv/bin/python prototypes/div_preserving_prolongation/held_bodies.py
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np
import trimesh

from benchmarks.staggered import job, shell_mesh
from engine import simulate
from engine.geometry.cache import GeometryCache

CANTILEVER = str(Path(__file__).resolve().parents[2] / "examples" / "cantilever.stl")


def spec(mesh: str, resolution: int, boundaries: list, analysis: dict | None = None) -> dict:
    return {"geometry": {"mesh": mesh}, "grid": {"resolution": resolution},
            "method": {"kind": "staggered", "solver": "iterative"},
            "material": {"youngs_modulus": 1e7, "poisson_ratio": 0.3, "density": 1000},
            "loads": {"gravity": [0, 0, -9.81]}, "boundaries": boundaries,
            "analysis": analysis or {"kind": "static"}, "solver": {"rtol": 1e-8, "max_iterations": 3000},
            "output": {"fields": ["displacement"], "surface": False}}


def solve(name: str, job_spec: dict, mesh: str, nus: tuple[float, ...] = (0.3, 0.4999)) -> None:
    for nu in nus:
        job_spec["material"]["poisson_ratio"] = nu
        t = time.perf_counter()
        r = simulate(job_spec, mesh, cache=GeometryCache(None))
        print(f"{name:34s} nu {nu}: {r.solver.iterations} iterations, {time.perf_counter() - t:.1f} s", flush=True)


def body(name: str, resolution: int, tmp: Path) -> tuple[dict, str]:
    """(the job spec at nu 0.3, its mesh path) of a held body: ``cantilever`` (the bundled one, clamped
    and loaded at its tip), ``dynamic`` (the same, 3 backward-Euler steps of 1 ms), ``bar`` (a 1 x 0.2 x
    0.2 bar tilted 17 degrees about an oblique axis, held within 0.16 m of its end face's centre: a cut
    clamp) or ``torus`` (radii 1, 0.3, held on its -x end, pressed on its +x end); meshes written to ``tmp``."""
    if name in ("cantilever", "dynamic"):
        clamp = {"kind": "displacement", "name": "clamp", "region": {"box": [[-0.1, -0.2, -0.2], [0.05, 0.2, 0.2]]}, "value": [0, 0, 0]}
        tip = {"kind": "traction", "name": "tip", "region": {"box": [[1.0, -0.2, -0.2], [1.1, 0.2, 0.2]]}, "value": [0, 0, -1000]}
        analysis = {"kind": "dynamic", "time_step": 1e-3, "steps": 3} if name == "dynamic" else None
        return spec(CANTILEVER, resolution, [clamp, tip], analysis), CANTILEVER
    if name == "bar":
        bar = trimesh.creation.box([1.0, 0.2, 0.2])
        bar.apply_translation([0.5, 0, 0])  # its end face centred on the origin, then tilted about an oblique axis
        bar.apply_transform(trimesh.transformations.rotation_matrix(np.radians(17), [0.3, 1, 0.2]))
        bar.export(tmp / "tilted.stl")
        held = {"kind": "displacement", "name": "end", "region": {"sphere": {"center": [0, 0, 0], "radius": 0.16}}, "value": [0, 0, 0]}
        return spec(str(tmp / "tilted.stl"), resolution, [held]), str(tmp / "tilted.stl")
    if name == "torus":
        trimesh.creation.torus(1.0, 0.3).export(tmp / "torus.stl")
        end = {"kind": "displacement", "name": "end", "region": {"box": [[-2, -2, -2], [-0.9, 2, 2]]}, "value": [0, 0, 0]}
        push = {"kind": "pressure", "name": "push", "region": {"box": [[0.9, -2, -2], [2, 2, 2]]}, "value": 1e4}
        return spec(str(tmp / "torus.stl"), resolution, [end, push]), str(tmp / "torus.stl")
    raise ValueError(f"unknown body {name!r}")


def main() -> None:
    tmp = Path(tempfile.mkdtemp())
    for title, name, resolution in (("bundled cantilever, 48", "cantilever", 48), ("cantilever, backward Euler, 32", "dynamic", 32),
                                    ("tilted bar, cut clamp, 40", "bar", 40), ("torus, clamp and pressure, 48", "torus", 48)):
        solve(title, *body(name, resolution, tmp))
    shell = tmp / "shell.stl"
    shell_mesh(shell)
    s = job(str(shell), 40, 0.3, 1e-6, "cpu")
    solve("held shell, 40", s, str(shell), (0.4999, 0.49999, 0.4999999))
    for analysis in ({"kind": "quasistatic", "steps": 2}, {"kind": "dynamic", "time_step": 1e-3, "steps": 2}):
        solve(f"held shell, 40, {analysis['kind']}", dict(job(str(shell), 40, 0.3, 1e-6, "cpu"), analysis=analysis), str(shell), (0.4999,))


if __name__ == "__main__":
    main()
