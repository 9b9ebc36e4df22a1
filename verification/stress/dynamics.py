"""Time steps: backward Euler after a sudden tip load.

- ``dynamic``: backward-Euler steps of 1e-5 s to 1 s after a sudden tip load, vs the static tip.
"""

from __future__ import annotations

import numpy as np

from verification.parts import cantilever
from verification.stress.rows import Row, Size, guarded, judge
from verification.stress.running import cantilever_job, cell_size, method_label, method_spec, solve, tip_deflection

def dynamic_case(method: str, size: Size) -> list[Row]:
    """Sudden tip load on the cantilever at rest, backward Euler at each time step: the tip deflection
    over the steps relative to the static one (a static run first). Backward Euler dissipates, so it
    stays within [0, 2]; at dt >> the first bending period (0.8 s) it relaxes to 1."""
    spec_m = method_spec(method, size)
    h = cell_size(method, size)
    bar = cantilever()
    rows, static = [], {}
    ref = Row("dynamic", method_label(spec_m), "static reference")

    def reference(row: Row) -> None:
        s = solve(cantilever_job(spec_m, h, bar), bar.mesh())
        static["tip"] = tip_deflection(s, bar)
        row.values["tip"] = static["tip"]
        row.quantity = f"tip={static['tip']:.4e}"
        judge(row, s)

    rows.append(guarded(ref, reference))
    for dt in size.time_steps:
        row = Row("dynamic", method_label(spec_m), f"dt={dt:g} steps={size.steps}")

        def body(row: Row, dt=dt) -> None:
            analysis = {"kind": "dynamic", "time_step": dt, "steps": size.steps}
            s = solve(cantilever_job(spec_m, h, bar, analysis=analysis), bar.mesh())
            tips = np.array([float(np.asarray(st.probes["displacement"])[0] @ bar.frame[1]) for st in s.outcome.steps])
            row.values.update(tips=tips.tolist())
            if "tip" in static:
                ratio = tips / static["tip"]
                row.values.update(ratio_max=float(ratio.max()), ratio_min=float(ratio.min()), ratio_last=float(ratio[-1]))
                row.quantity = f"tip/static max={ratio.max():.3g} last={ratio[-1]:.3g}"
                if ratio.max() > 2.0 + 1e-6 or ratio.min() < -1e-6:
                    row.note = "tip outside [0, 2] x static: backward Euler should not overshoot"
            judge(row, s)

        rows.append(guarded(row, body))
    return rows
