"""DG method floor: a sphere shell on a 16^3 grid, k = 2, static; stages and assembly throughput.

    .venv/bin/python -m benchmarks.dg [--resolution 16] [--degree 2] [--repeats 3] [--json out.json]
                                      [--solver auto|direct|iterative] [--nu 0.3]
    .venv/bin/python -m benchmarks.dg --solvers [--resolution 16] [--degree 2]

``--solvers`` builds the same system once and times its linear solvers side by side, each in its
own spawned process: MKL PARDISO Cholesky (the direct one), scipy SuperLU (the fallback), Taichi's
SparseSolver LLT, pyamg smoothed-aggregation CG (rtol 1e-10, rigid modes as near-null space) and the
engine's p-multigrid CG (rtol 1e-10; the iterative one), or those named by ``--which``.

Shell: icospheres (subdivisions 5) of radius 1 and 0.6, clamped below z = -0.8, gravity,
E = 1e6, nu = 0.3 (``--nu``), IP, penalty 10. Each repeat runs in its own spawned process (cold geometry
cache, warm Taichi kernel cache after the first); medians over repeats.
"""


import argparse
import json
import multiprocessing as mp
import platform
import statistics
import time
from pathlib import Path

from .memory import peak_rss_bytes


def _shell_method(resolution: int, degree: int, solver: str = "auto", nu: float = 0.3):
    """(DGElasticity, slicing seconds, discretization seconds) of the benchmark shell."""
    import numpy as np
    import trimesh

    from engine.boundary import Prescribed
    from engine.dg.elasticity import DGElasticity
    from engine.geometry.slicing import slice_cells
    from engine.geometry.surface import Surface
    from engine.grid import make_grid
    from engine.material import Material
    from engine.regions import Halfspaces
    from engine.runtime import init

    init("cpu", "f64")
    outer = trimesh.creation.icosphere(subdivisions=5, radius=1.0)
    inner = trimesh.creation.icosphere(subdivisions=5, radius=0.6)
    inner.invert()
    mesh = trimesh.util.concatenate([outer, inner])
    surface = Surface(mesh.vertices.astype(float), mesh.faces.astype("int64"))
    t0 = time.perf_counter()
    grid = make_grid(*surface.bounds, resolution=resolution)
    cut = slice_cells(surface, grid)
    t1 = time.perf_counter()
    clamp = Halfspaces(np.array([[0, 0, 1.0]]), np.array([-0.8]))
    m = DGElasticity(cut=cut, surface=surface, material=Material(1e6, nu, 1000), degree=degree, flux="ip",
                     penalty=10, prescribed=[Prescribed(clamp, (0, 0, 0), "base")],
                     body_force=np.array([0, 0, -9.81e3]), solver_kind=solver)
    return m, t1 - t0, time.perf_counter() - t1


def _run(resolution: int, degree: int, solver: str, nu: float, queue) -> None:
    m, slicing, discretization = _shell_method(resolution, degree, solver, nu)
    t = time.perf_counter()
    st = m.solve()
    solve = time.perf_counter() - t
    queue.put({
        "elements": m.elements.count, "pieces": m.cut.num_pieces, "merged": m.elements.merged, "dofs": m.size,
        "slicing_s": slicing, "discretization_s": discretization, "solve_s": solve,
        "total_s": slicing + discretization + solve,
        "stages": m.timings, "nnz": int(m.matrix.nnz), "residual": st.stats.residual, "eta": m.eta,
        "iterations": st.stats.iterations,
        "assembly_elements_per_s": m.elements.count / (m.timings["element_blocks"] + m.timings["assembly"]),
        "peak_rss_gib": peak_rss_bytes() / 2**30,
        "backend": m.solver.backend,
    })


def _solver(name: str, resolution: int, degree: int, queue) -> None:
    """Time one linear solver on the shell's system: setup (factorisation / hierarchy) and solve."""
    import numpy as np
    import scipy.sparse as sp

    m, _, _ = _shell_method(resolution, degree, "direct")
    A = sp.csr_matrix(m.matrix)
    b = m._rhs(1.0, 1.0, None)
    reference = m.solver.apply_inverse(b)
    m.release_solver()
    t0 = time.perf_counter()
    if name == "pardiso":
        from engine.solvers.direct import Cholesky

        f = Cholesky(A)
        t1 = time.perf_counter()
        x = f.solve(b)
    elif name == "superlu":
        import scipy.sparse.linalg as spla

        lu = spla.splu(sp.csc_matrix(A), diag_pivot_thresh=0.0, options={"SymmetricMode": True})
        t1 = time.perf_counter()
        x = lu.solve(b)
    elif name == "taichi-llt":
        import gstaichi as ti  # a benchmark, not engine code: the runtime rule is for engine/

        coo = A.tocoo()
        rows, cols, vals = coo.row.astype(np.int32), coo.col.astype(np.int32), coo.data.astype(np.float64)
        builder = ti.linalg.SparseMatrixBuilder(A.shape[0], A.shape[1], max_num_triplets=len(vals), dtype=ti.f64)

        @ti.kernel(fastcache=True)
        def fill(K: ti.types.sparse_matrix_builder(), r: ti.types.ndarray(), c: ti.types.ndarray(),
                 v: ti.types.ndarray()):
            for k in range(r.shape[0]):
                K[r[k], c[k]] += v[k]

        fill(builder, rows, cols, vals)
        K = builder.build()
        solver = ti.linalg.SparseSolver(dtype=ti.f64, solver_type="LLT")
        solver.analyze_pattern(K)
        solver.factorize(K)
        t1 = time.perf_counter()
        bt = ti.ndarray(ti.f64, shape=A.shape[0])
        bt.from_numpy(b)
        x = solver.solve(bt).to_numpy()
    elif name == "pyamg-cg":
        import pyamg
        import scipy.sparse.linalg as spla

        B = np.stack([m._mode_coefficients(np.arange(m.elements.count), np.zeros(3), np.eye(6)[:, j:j + 1])[:, 0]
                      for j in range(6)], axis=1)
        ml = pyamg.smoothed_aggregation_solver(A, B=B, symmetry="symmetric")
        M = ml.aspreconditioner(cycle="V")
        t1 = time.perf_counter()
        its = []
        x, info = spla.cg(A, b, rtol=1e-10, M=M, maxiter=2000, callback=lambda xk: its.append(1))
        if info != 0:
            x = np.full_like(b, np.nan)
    elif name == "pmg-cg":
        from engine.dg.elasticity import degree_chain
        from engine.solvers.pmultigrid import PMultigrid

        pmg = PMultigrid(A, 3 * m.n, degree_chain(degree), rtol=1e-10)
        t1 = time.perf_counter()
        x, stats = pmg.solve(b)
        its = [1] * stats.iterations
    else:
        raise SystemExit(f"unknown solver {name}")
    t2 = time.perf_counter()
    queue.put({"solver": name, "dofs": A.shape[0], "nnz": int(A.nnz), "setup_s": t1 - t0, "solve_s": t2 - t1,
               "total_s": t2 - t0, "iterations": len(its) if name in ("pyamg-cg", "pmg-cg") else 1,
               "residual": float(np.linalg.norm(A @ x - b) / np.linalg.norm(b)),
               "difference": float(np.linalg.norm(x - reference) / np.linalg.norm(reference)),
               "peak_rss_gib": peak_rss_bytes() / 2**30})


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=16)
    ap.add_argument("--degree", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", type=Path)
    ap.add_argument("--solvers", action="store_true", help="time the linear solvers side by side")
    ap.add_argument("--nu", type=float, default=0.3, help="Poisson's ratio of the whole-job runs")
    ap.add_argument("--which", nargs="+", default=["pardiso", "superlu", "taichi-llt", "pyamg-cg", "pmg-cg"],
                    help="the solvers --solvers times")
    ap.add_argument("--solver", choices=("auto", "direct", "iterative"), default="auto",
                    help="the DG solver of the whole-job runs (auto: p-multigrid CG above 100,000 unknowns)")
    a = ap.parse_args()
    ctx = mp.get_context("spawn")
    if a.solvers:
        rows = []
        for name in a.which:
            q = ctx.Queue()
            p = ctx.Process(target=_solver, args=(name, a.resolution, a.degree, q))
            p.start()
            p.join()
            rows.append(q.get() if p.exitcode == 0 else {"solver": name, "failed": f"exit code {p.exitcode}"})
            print(json.dumps(rows[-1]), flush=True)
        if a.json:
            a.json.write_text(json.dumps(rows, indent=1))
        return
    runs = []
    for _ in range(a.repeats):
        q = ctx.Queue()
        p = ctx.Process(target=_run, args=(a.resolution, a.degree, a.solver, a.nu, q))
        p.start()
        runs.append(q.get())
        p.join()
        print(json.dumps(runs[-1]), flush=True)
    keys = ("slicing_s", "discretization_s", "solve_s", "total_s", "assembly_elements_per_s")
    summary = {k: statistics.median(r[k] for r in runs) for k in keys}
    summary.update({"machine": platform.processor() or platform.machine(), "runs": runs})
    print("median:", json.dumps({k: round(v, 3) for k, v in summary.items() if k in keys}))
    if a.json:
        a.json.write_text(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
