"""DOLFINx as the accuracy benchmark's peer (issue 23): P1 / P2 on the peer's meshes, PETSc CG + GAMG.

The meshes are ``benchmarks.peer``'s (gmsh of the CAD geometry, second order with its nodes on the
true surface for curved P2; fTetWild's tetrahedra of the STL for ``geometry="stl"``), and so are the
problems, the roles of the boundary facets and the probes: the same discrete problem as the
scikit-fem peer, solved by DOLFINx instead (``benchmarks/dolfinx_job.py`` says how: quadrature as
the scikit-fem peer, GAMG given the 6 rigid-body modes as near-null space, the same relative
tolerance on the unpreconditioned residual).

DOLFINx has no pip wheel; Debian / Ubuntu package it for the system Python, which is where it runs
(never in the project's virtual environment, and never a runtime dependency)::

    apt-get install -y --no-install-recommends python3-dolfinx   # Debian 12: DOLFINx 0.5.2, PETSc 3.18

This module (the virtual environment) meshes as the scikit-fem peer does, writes the job's arrays to
a temporary .npz and hands it to a worker process of that interpreter (``SYSTEM_PYTHON``, or
``$VOXELASTIC_DOLFINX_PYTHON``) running ``dolfinx_job.py``, which answers with the displacement and
its gradient at the probes; von Mises and the errors are computed here as for the scikit-fem peer.

What a job's ``seconds`` counts: meshing (gmsh or fTetWild, and the facets' roles, as the scikit-fem
peer's "mesh" stage), and in the worker DOLFINx's mesh from the arrays with its facet tags
("dolfinx_mesh"), assembly ("assembly": on the first job of a worker FFCx compiles the forms, or
loads them from its disk cache, ``~/.cache/fenics``), GAMG setup, CG and the rigid modes' removal
("solve"), and the probes ("probe"). On the job that starts the worker (cold) also "start": the
interpreter's start and the imports of DOLFINx, PETSc, UFL and Basix. Not counted: the hand-over of
the arrays (.npz written and read, the answer read back; "transfer", reported), which a DOLFINx user
meshing in the same process would not pay. Warm is the second job of the same worker.

Command (from the repository root)::

    .venv/bin/python -m benchmarks.dolfinx_peer --problem ball --order 2 --h 0.4 --geometry curved
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.dolfinx_job import DIRICHLET, EDGES, LOAD, facet_keys
from benchmarks.peer import (
    _GmshMesh,
    check_arguments,
    edge_nodes,
    facet_roles,
    make_mesh,
    peer_problem,
    record,
    von_mises_at,
)
from verification.problems import Problem

SYSTEM_PYTHON = "/usr/bin/python3"
SCRIPT = Path(__file__).with_name("dolfinx_job.py")
FACES = ((1, 2, 3), (0, 2, 3), (0, 1, 3), (0, 1, 2))


def python() -> str:
    """The interpreter that has DOLFINx."""
    return os.environ.get("VOXELASTIC_DOLFINX_PYTHON", SYSTEM_PYTHON)


def _environment() -> dict:
    """This process's environment without what would point the system Python at the virtual one."""
    return {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}


def available() -> str | None:
    """DOLFINx's version where :func:`python` imports it, else None."""
    try:
        out = subprocess.run([python(), "-c", "import dolfinx.fem.petsc; print(dolfinx.__version__)"],
                             capture_output=True, text=True, timeout=120, env=_environment())
    except (OSError, subprocess.TimeoutExpired):
        return None
    return out.stdout.strip() if out.returncode == 0 else None


class Worker:
    """One DOLFINx process (``dolfinx_job.py``), started by the first job that needs it, reused after."""

    def __init__(self) -> None:
        self.process: subprocess.Popen | None = None
        self.versions: dict | None = None
        self._scratch = tempfile.TemporaryDirectory(prefix="voxelastic-dolfinx-")

    def start(self) -> float:
        """Start the worker; wall seconds until it has imported its libraries."""
        t = time.perf_counter()
        self.process = subprocess.Popen([python(), str(SCRIPT)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                        text=True, env=_environment())
        self.versions = self._answer()["ready"]
        return time.perf_counter() - t

    def solve(self, arrays: dict) -> tuple[dict, dict, float]:
        """(the worker's answer, its arrays, wall seconds of the round trip) for one job."""
        t = time.perf_counter()
        job, out = Path(self._scratch.name, "job.npz"), Path(self._scratch.name, "out.npz")
        np.savez(job, **arrays)
        self.process.stdin.write(json.dumps({"job": str(job), "out": str(out)}) + "\n")
        self.process.stdin.flush()
        answer = self._answer()
        if "error" in answer:
            raise RuntimeError(f"DOLFINx job failed: {answer['error']}")
        with np.load(out) as data:
            fields = {k: data[k] for k in data.files}
        return answer["done"], fields, time.perf_counter() - t

    def _answer(self) -> dict:
        line = self.process.stdout.readline()
        if not line:
            raise RuntimeError(f"the DOLFINx worker ({python()} {SCRIPT.name}) ended with exit code "
                               f"{self.process.wait()}; its stderr says why")
        return json.loads(line)

    def close(self) -> None:
        if self.process is not None:
            self.process.stdin.close()
            try:
                self.process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
            self.process = None
        self._scratch.cleanup()

    def __enter__(self) -> Worker:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def boundary_faces(cells: np.ndarray, n: int) -> np.ndarray:
    """The faces [F, 3] (vertex indices < n) of tetrahedra [E, 4] that belong to one tetrahedron only."""
    faces = cells[:, FACES].reshape(-1, 3)
    _, first, count = np.unique(facet_keys(faces, n), return_index=True, return_counts=True)
    return faces[first[count == 1]]


def job_arrays(prob: Problem, gm: _GmshMesh, order: int, rtol: float, outside: str) -> dict:
    """The job file's arrays (``dolfinx_job``'s docstring) for the problem on the mesh ``gm``."""
    if prob.dim != 3:
        raise ValueError(f"the DOLFINx peer: 3D problems, got {prob.name!r}")
    points, cells = gm.points, gm.cells
    if gm.edge_pairs is not None:  # second order: gmsh's edge nodes after the vertices
        nodes = edge_nodes(gm, cells[:, EDGES].reshape(-1, 2)).reshape(len(cells), -1)
        points, cells = np.vstack([points, gm.edge_points]), np.hstack([cells, len(gm.points) + nodes])
    facets = boundary_faces(gm.cells, len(gm.points))
    held, loaded = facet_roles(prob, gm.points[facets].mean(axis=1))
    if prob.name == "lame":
        load = {"load": "pressure", "pressure": prob.pressure, "floating": True}
    elif np.all(held | loaded) and prob.body_force is not None:  # the divergence form of dolfinx_job._load
        load = {"load": "exact", "pressure": 0.0, "floating": False}
    else:
        raise ValueError(f"the DOLFINx peer: no load for {prob.name!r}")
    roles = np.where(held, DIRICHLET, np.where(loaded, LOAD, 0)).astype(np.int32)
    return {"points": points, "cells": cells, "order": order, "facets": facets, "roles": roles,
            "probes": prob.probes, "lame": np.array(prob.lame), "rtol": rtol, "outside": outside,
            "problem": prob.name, **load}


def run_dolfinx(problem_name: str, order: int, h: float, rtol: float = 1e-10, geometry: str = "straight",
                outside: str = "error", worker: Worker | None = None) -> dict:
    """Solve one benchmark problem with DOLFINx P``order`` on the scikit-fem peer's mesh of size h [m].

    The record of ``benchmarks.peer.run_peer`` (method "DOLFINx P...", geometry and outside as
    there), with ``seconds`` as the module docstring says, ``stages`` and ``versions``. ``worker``:
    a running worker makes this a warm job; a new one is started here (and its start counted), a
    worker made here is closed at the end.
    """
    import gmsh  # noqa: F401  (imports excluded, as the scikit-fem peer's)
    import pytetwild  # noqa: F401

    check_arguments(order, geometry, outside)
    prob = peer_problem(problem_name)
    own = worker is None
    worker = Worker() if own else worker
    try:
        t = time.perf_counter()
        arrays = job_arrays(prob, make_mesh(prob, h, geometry), order, rtol, outside)
        stages = {"mesh": time.perf_counter() - t}
        if worker.process is None:
            stages["start"] = worker.start()
        answer, fields, wall = worker.solve(arrays)
    finally:
        if own:
            worker.close()
    stages.update({("dolfinx_mesh" if k == "mesh" else k): v for k, v in answer.pop("stages").items()})
    seconds = sum(stages.values())
    stages["transfer"] = wall - sum(v for k, v in stages.items() if k not in ("mesh", "start"))
    vm = von_mises_at(prob, fields["gradient"])
    return record(f"DOLFINx P{order}", geometry, prob, problem_name, h, fields["displacement"], vm,
                  seconds=seconds, stages=stages, versions=worker.versions, **answer)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--problem", required=True, choices=["lame", "ball"])
    parser.add_argument("--order", type=int, default=1, choices=[1, 2])
    parser.add_argument("--h", type=float, required=True, help="mesh size [m]")
    parser.add_argument("--rtol", type=float, default=1e-10)
    parser.add_argument("--geometry", default="straight", choices=["straight", "curved", "stl"])
    parser.add_argument("--outside", default="error", choices=["error", "nearest"])
    args = parser.parse_args(argv)
    if available() is None:
        sys.exit(f"{python()} cannot import dolfinx: apt-get install -y --no-install-recommends python3-dolfinx")
    out = run_dolfinx(args.problem, args.order, args.h, args.rtol, args.geometry, args.outside)
    print(json.dumps({k: v for k, v in out.items() if k not in ("displacement", "von_mises")}, indent=1))


if __name__ == "__main__":
    main()
