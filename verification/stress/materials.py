"""Material extremes on the cantilever: Poisson's ratio towards 1/2, Young's modulus over nine
decades, and 10% strain (linear and corotated).

- ``poisson``: nu = 0.3, 0.45, 0.49, 0.499, 0.4999: tip deflection over Timoshenko beam theory
  (locking), iterations and condition growth.
- ``youngs``: E = 1, 1e3, 1e9 with the traction scaled with E (displacement identical) and with
  one fixed traction (displacement * E identical); summary rows compare every cell to 1e-8.
- ``large_strain``: bending to 10% surface strain, linear and corotated, vs the elastica.
"""

from __future__ import annotations

import numpy as np

from verification.parts import E0, LENGTH, NU0, TIP_TRACTION, WIDTH, cantilever, elastica_tip, timoshenko_tip
from verification.stress.rows import SCALING_LIMIT, Row, Size, guarded, judge
from verification.stress.running import cantilever_job, cell_size, h_label, method_label, method_spec, solve, tip_deflection

def poisson_case(method: str, size: Size, nu: float) -> Row:
    """Cantilever at Poisson's ratio nu: tip deflection over Timoshenko beam theory (locking shows
    as a ratio falling with nu; beam theory itself ignores the clamp's 3D constraint)."""
    spec_m = method_spec(method, size)
    h = cell_size(method, size)
    bar = cantilever()
    row = Row("poisson", method_label(spec_m), f"nu={nu:g} {h_label(h)}")

    def body(row: Row) -> None:
        s = solve(cantilever_job(spec_m, h, bar, nu=nu), bar.mesh())
        beam = timoshenko_tip(TIP_TRACTION * WIDTH**2, LENGTH, WIDTH, E0, nu)
        tip = tip_deflection(s, bar)
        row.values.update(tip=tip, beam=beam, ratio=tip / beam)
        row.quantity = f"tip/beam={tip / beam:.4f}"
        judge(row, s)

    return guarded(row, body)


def youngs_case(method: str, size: Size) -> list[Row]:
    """E sweep: traction scaled with E (the displacement must not change) and one fixed traction
    (displacement * E must not change); a summary row per variant compares every material cell's
    displacement and the probes with the first E's, relative to its largest value."""
    spec_m = method_spec(method, size)
    h = cell_size(method, size)
    bar = cantilever()
    rows = []
    for variant in ("scaled", "fixed"):
        fields: list[np.ndarray] = []
        for E in size.youngs:
            traction = TIP_TRACTION * E / E0 if variant == "scaled" else TIP_TRACTION
            row = Row("youngs", method_label(spec_m), f"E={E:g} T={traction:g}")

            def body(row: Row, E=E, traction=traction, variant=variant) -> None:
                s = solve(cantilever_job(spec_m, h, bar, youngs=E, traction=traction), bar.mesh())
                scale = 1.0 if variant == "scaled" else E / E0  # both: the E0 run's displacement
                u = np.concatenate([s.final.cells["displacement"][s.material].ravel(), s.probe().ravel()]) * scale
                fields.append(u)
                tip = tip_deflection(s, bar) * scale
                row.values["tip"] = tip
                row.quantity = f"tip={tip:.6e}" if variant == "scaled" else f"tip*E/E0={tip:.6e}"
                judge(row, s)

            rows.append(guarded(row, body))
        what = "u" if variant == "scaled" else "u*E"
        summary = Row("youngs", method_label(spec_m), f"{variant} T: {what} over E={','.join(f'{e:g}' for e in size.youngs)}")
        if len(fields) == len(size.youngs):
            ref = fields[0]
            diff = max(float(np.abs(u - ref).max() / np.abs(ref).max()) for u in fields[1:])
            summary.quantity = f"max rel diff={diff:.2e}"
            summary.passed = diff <= SCALING_LIMIT
            summary.values.update(max_relative_difference=diff)
            summary.note = "" if summary.passed else f"above {SCALING_LIMIT:g}"
        else:
            summary.note = f"{len(size.youngs) - len(fields)} run(s) failed; nothing to compare"
        rows.append(summary)
    return rows


def large_strain_case(method: str, size: Size) -> list[Row]:
    """Bending to 10% surface strain at the clamp (linear beam theory) under a dead tip load, linear
    and corotated: tip deflection over linear beam theory and over the elastica (inextensible,
    no shear), and the largest normal strain at a cell centre (half a cell inside the surface)."""
    spec_m = method_spec(method, size)
    h = cell_size(method, size)
    bar = cantilever()
    inertia = WIDTH**4 / 12
    force = 0.1 * E0 * inertia / (LENGTH * WIDTH / 2)  # M c / (E I) = 10% at the clamp
    traction = force / WIDTH**2
    beam = timoshenko_tip(force, LENGTH, WIDTH, E0, NU0)
    elastica = elastica_tip(force * LENGTH**2 / (E0 * inertia)) * LENGTH
    rows = []
    for model in ("linear", "corotated"):
        row = Row("large_strain", method_label(spec_m), f"{model} T={traction:.4g}")

        def body(row: Row, model=model) -> None:
            s = solve(cantilever_job(spec_m, h, bar, traction=traction, model=model,
                                     fields=("displacement", "strain", "stress")), bar.mesh())
            tip = tip_deflection(s, bar)
            strain = float(np.abs(s.final.cells["strain"][s.material][:, :3]).max())
            row.values.update(tip=tip, beam=beam, elastica=elastica, max_strain=strain)
            row.quantity = f"tip/beam={tip / beam:.3f} tip/elastica={tip / elastica:.3f} max|eps|={strain:.3f}"
            judge(row, s)

        rows.append(guarded(row, body))
    return rows
