"""Batches of tiny dense solves on OpenBLAS's default threads and on one (engine.blas): 2,000
lower-triangular 10 x 10 systems against identities, ``np.linalg.solve``, repeated.

    .venv/bin/python -m benchmarks.blas_batches [--repeats 5]

Prints the seconds of each repeat both ways. The difference shows when other work shares the cores
(the threads then wait on each other); on an idle machine both take milliseconds.
"""

from __future__ import annotations

import argparse
import json
import time


def main(argv: list[str] | None = None) -> int:
    import numpy as np

    from engine.blas import one_thread

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args(argv)
    a = np.tril(np.random.default_rng(0).uniform(size=(2000, 10, 10))) + 3 * np.eye(10)
    eye = np.broadcast_to(np.eye(10), a.shape)
    rows = {"default_threads_s": [], "one_thread_s": []}
    for _ in range(args.repeats):
        t = time.perf_counter()
        np.linalg.solve(a, eye)
        rows["default_threads_s"].append(round(time.perf_counter() - t, 4))
        with one_thread():
            t = time.perf_counter()
            np.linalg.solve(a, eye)
            rows["one_thread_s"].append(round(time.perf_counter() - t, 4))
    print(json.dumps(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
