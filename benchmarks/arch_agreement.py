"""The same job on two Taichi backends: the bundled cantilever (staggered) at nu = 0.3 and 0.4999,
each run through the CLI with ``solver.arch`` cpu and then cuda, the cell displacements compared.

    .venv/bin/python -m benchmarks.arch_agreement OUT_DIR [--archs cpu cuda]

Prints per job the wall time of the CLI process and, per Poisson ratio, max |u_a - u_b| / max |u|
over the material cells and both solves' CG iterations. Where no GPU is present Taichi's cuda
falls back to the CPU (docs/benchmarks.md, "The CUDA backend on a lent GPU").
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def run_job(out: Path, arch: str, nu: float) -> Path:
    """Run the cantilever with ``arch`` and Poisson's ratio ``nu``; returns the result path."""
    spec = json.loads((EXAMPLES / "cantilever.json").read_text())
    spec["material"]["poisson_ratio"] = nu
    spec["solver"] = {**spec.get("solver", {}), "arch": arch}
    spec["geometry"]["mesh"] = str(EXAMPLES / "cantilever.stl")
    job, result = out / f"job_{arch}_{nu:g}.json", out / f"result_{arch}_{nu:g}.h5"
    job.write_text(json.dumps(spec))
    t = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "engine.cli", "run", str(job), "-o", str(result)], capture_output=True, text=True)
    print(f"{arch} nu={nu:g}: exit {r.returncode}, {time.perf_counter() - t:.1f} s", flush=True)
    if r.returncode:
        raise SystemExit(r.stderr[-2000:])
    return result


def main(argv: list[str] | None = None) -> int:
    import h5py
    import numpy as np

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", type=Path)
    ap.add_argument("--archs", nargs=2, default=["cpu", "cuda"])
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    for nu in (0.3, 0.4999):
        a, b = (run_job(args.out, arch, nu) for arch in args.archs)
        with h5py.File(a) as fa, h5py.File(b) as fb:
            ua, ub = fa["fields/displacement"][()], fb["fields/displacement"][()]
            m = np.isfinite(ua)
            diff = np.abs(ua[m] - ub[m]).max() / np.abs(ua[m]).max()
            print(f"nu={nu:g}: max |u_{args.archs[0]} - u_{args.archs[1]}| / max |u| = {diff:.3e}; CG iterations "
                  f"{fa['solver'].attrs['iterations']} / {fb['solver'].attrs['iterations']}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
