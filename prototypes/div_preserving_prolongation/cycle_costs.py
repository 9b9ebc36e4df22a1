"""Where the held shell's job spends its time: per-call medians of the fine level's residual and curl
smoother (and the smoother's parts), then the whole job with the multigrid's calls timed, per nu.

    PYTHONPATH=. .venv/bin/python prototypes/div_preserving_prolongation/cycle_costs.py RES NU... [levels=N]

``levels=N`` caps the job's hierarchy at N levels (the coarsest factorised).

Each nu runs in its own process (Taichi keeps one precision per process; timings stay apart).
"""

from __future__ import annotations

import collections
import multiprocessing as mp
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))


def _median_ms(f, sync, n: int = 20) -> float:
    f()
    times = []
    for _ in range(n):
        t = time.perf_counter()
        f()
        sync()
        times.append(time.perf_counter() - t)
    return sorted(times)[n // 2] * 1e3


def _calls(res: int, nu: float) -> None:
    from engine.staggered import elasticity, kernels, smoother_kernels
    from harness import held_shell

    captured = {}

    def grab(self, *args, **kwargs):
        captured["problem"] = self
        raise SystemExit

    elasticity.StaggeredElasticity.solve = grab
    try:
        held_shell(res, nu)
    except SystemExit:
        pass
    m = captured["problem"].multigrid
    lv = m.levels[0]
    r, x, step = lv.zeros(), lv.zeros(), lv.zeros()
    kernels.random_fill(lv.dim, r, lv.mask, 3)
    sync = lambda: kernels.dot(lv.dim, x, x)  # noqa: E731
    out = {"residual": _median_ms(lambda: lv.residual(x, r, step), sync),
           "copy": _median_ms(lambda: kernels.copy(lv.dim, r, step), sync)}
    if m.robust:
        sm = m.curls[0]
        out["curl smoother"] = _median_ms(lambda: sm.apply(smoother_kernels.STEP, r, x, step, 0.5, 0.1), sync)
        out["  curls' residual"] = _median_ms(lambda: smoother_kernels.curl_residual(lv.dim, sm.n, lv.nbr, r, sm.inv_theta, sm.t), sync)
        out["  face step"] = _median_ms(lambda: smoother_kernels.hybrid_step(lv.dim, smoother_kernels.STEP, sm.n, lv.nbr, lv.dinv, lv.mask, r, sm.t, x, step, 0.5, 0.1), sync)
        if sm.band is not None:
            comp, pos, indptr, indices, data = sm.band
            out["  band gather"] = _median_ms(lambda: kernels.gather(r, comp, pos, sm.band_in), sync)
            out["  band CSR"] = _median_ms(lambda: kernels.csr_apply(indptr, indices, data, sm.band_in, sm.band_out, 0), sync)
            out["  band add"] = _median_ms(lambda: smoother_kernels.band_add(smoother_kernels.STEP, comp, pos, sm.band_out, lv.mask, 0.1, step, x), sync)
    print(f"nu {nu}, {res}^3, fine level per call (medians of 20, ms):", flush=True)
    for k, v in out.items():
        print(f"  {k:20s} {v:7.2f}", flush=True)


def _job(res: int, nu: float, levels: int | None) -> None:
    from benchmarks.staggered import job, shell_mesh
    from engine.geometry.cache import GeometryCache
    from engine.pipeline import Limits, run
    from engine.staggered import multigrid

    seconds, calls = collections.defaultdict(float), collections.Counter()

    def timed(owner, name, key):
        f = getattr(owner, name)

        def g(*args, **kwargs):
            t = time.perf_counter()
            out = f(*args, **kwargs)
            seconds[key] += time.perf_counter() - t
            calls[key] += 1
            return out

        setattr(owner, name, g)

    if levels is not None:
        init = multigrid.Multigrid.__init__

        def capped(self, fine, *, max_levels=12, **kwargs):
            init(self, fine, max_levels=min(max_levels, levels), **kwargs)

        multigrid.Multigrid.__init__ = capped
    timed(multigrid.Multigrid, "precondition", "cycle")
    timed(multigrid.Multigrid, "__init__", "multigrid setup")
    with tempfile.TemporaryDirectory() as tmp:
        mesh = Path(tmp) / "shell.stl"
        shell_mesh(mesh)
        t = time.perf_counter()
        r = run(job(str(mesh), res, nu, 1e-6, "cpu"), cache=GeometryCache(None), limits=Limits(max_memory_bytes=64 * 2**30))
        wall = time.perf_counter() - t
    print(f"nu {nu}, {res}^3 job: {wall:.1f} s, {r.solver.iterations} iterations; "
          + ", ".join(f"{k} {v:.2f}" for k, v in r.solver.stage_times.items()), flush=True)
    for k in seconds:
        print(f"  {k:20s} {seconds[k]:7.2f} s in {calls[k]} calls ({seconds[k] / calls[k]:.3f} s each)", flush=True)


def main(res: int, nus: list[float], levels: int | None) -> None:
    ctx = mp.get_context("spawn")
    for nu in nus:
        for target, args in ((_calls, (res, nu)), (_job, (res, nu, levels))):
            p = ctx.Process(target=target, args=args)
            p.start()
            p.join()


if __name__ == "__main__":
    cap = [int(v.split("=")[1]) for v in sys.argv[2:] if v.startswith("levels=")]
    main(int(sys.argv[1]), [float(v) for v in sys.argv[2:] if not v.startswith("levels=")], cap[0] if cap else None)
