"""Held surfaces near incompressibility (issue 21): the staggered holds with and without the held cut
cells' finite-volume divergence (engine/staggered/held.py), DG k = 2 beside.

    .venv/bin/python -m benchmarks.held_incompressible sphere --nu 0.3 0.49 0.4999 --h 0.1 0.05 0.025
    .venv/bin/python -m benchmarks.held_incompressible annulus --nu 0.3 0.4999 --h 0.05 0.025 0.0125
    .venv/bin/python -m benchmarks.held_incompressible rim --nu 0.3 0.4999 --h 0.1 0.05 0.025 --reference 0.016667
    .venv/bin/python -m benchmarks.held_incompressible pressure --nu 0.3 0.4999 --h 0.1 0.05 --dg 0.25 0.125

``sphere``/``annulus``: relative L2 error against the exact solution (verification/held.py); ``rim``:
the sphere clamped below z = 0.3 (no closed form), against the staggered method at cell size
``--reference`` (``--reference-dg``: DG k = 2 there instead); ``pressure``: the clamped sphere's pressure
against its exact constant (relative L2 at the probes, largest relative error over the cells) and, for
the staggered method, the pressure's spikes where the sphere is clamped below z = 0.3
(``verification.held.rim_pressure_spikes``). Each staggered row
runs twice: "finite volume" (the engine) and "Nitsche only" (APERTURE_RATIO raised past the job's
lambda / mu). ``--dg`` adds DG k = 2 rows at the sizes given there.
"""

from __future__ import annotations

import argparse
import time

from engine.staggered import held
from verification import held as cases


def _staggered(run, finite_volume: bool):
    saved = held.APERTURE_RATIO
    held.APERTURE_RATIO = saved if finite_volume else float("inf")
    try:
        return run()
    finally:
        held.APERTURE_RATIO = saved


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("case", choices=["sphere", "annulus", "rim", "pressure"])
    parser.add_argument("--nu", type=float, nargs="+", default=[0.3, 0.4999])
    parser.add_argument("--h", type=float, nargs="+", default=[0.1, 0.05])
    parser.add_argument("--dg", type=float, nargs="*", default=[], help="DG k = 2 cell sizes (sphere, rim)")
    parser.add_argument("--reference", type=float, default=1 / 60, help="rim: the reference's cell size [m]")
    parser.add_argument("--reference-dg", action="store_true", help="rim: DG k = 2 as the reference")
    args = parser.parse_args(argv)
    dg = {"kind": "dg", "degree": 2}
    if args.case == "pressure":
        for nu in args.nu:
            for label, method, sizes in (("staggered", None, args.h), ("DG k = 2", dg, args.dg)):
                for h in sizes:
                    t = time.perf_counter()
                    probes, cells = cases.clamped_sphere_pressure_error(nu, h, method)
                    spikes = cases.rim_pressure_spikes(nu, h, method) if method is None else float("nan")
                    print(f"pressure nu={nu:g} {label} h={h:g}: probes {probes:.3e}, cells at most {cells:.3e}; "
                          f"clamped below z = 0.3: spikes {spikes:.3g} ({time.perf_counter() - t:.1f} s)", flush=True)
        return
    for nu in args.nu:
        reference = None
        if args.case == "rim":
            reference = cases.partly_clamped_sphere(nu, args.reference, dg if args.reference_dg else None)[0]
        rows = [("finite volume", True), ("Nitsche only", False)]
        for label, fv in rows:
            for h in args.h:
                t = time.perf_counter()
                if args.case == "sphere":
                    error = _staggered(lambda: cases.clamped_sphere_error(nu, h)[0], fv)
                elif args.case == "annulus":
                    error = _staggered(lambda: cases.clamped_annulus_error(nu, h)[0], fv)
                else:
                    error = cases.difference(_staggered(lambda: cases.partly_clamped_sphere(nu, h)[0], fv), reference)
                print(f"{args.case} nu={nu:g} staggered {label:13s} h={h:g}: {error:.3e} ({time.perf_counter() - t:.1f} s)",
                      flush=True)
        for h in args.dg if args.case != "annulus" else []:
            t = time.perf_counter()
            if args.case == "sphere":
                error = cases.clamped_sphere_error(nu, h, dg)[0]
            else:
                error = cases.difference(cases.partly_clamped_sphere(nu, h, dg)[0], reference)
            print(f"{args.case} nu={nu:g} DG k = 2 h={h:g}: {error:.3e} ({time.perf_counter() - t:.1f} s)", flush=True)


if __name__ == "__main__":
    main()
