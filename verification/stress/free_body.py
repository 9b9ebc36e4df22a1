"""Free bodies: the long bar without displacement boundaries.

- ``free_body``: the 2 m bar pulled at both ends, along x and rotated (balanced: solved off the
  rigid modes with a warning; any error fails), and at one end (``UnbalancedLoadError`` "do not
  balance" required).
"""

from __future__ import annotations

from verification.parts import ALIGNED, E0, LONG, ROTATED, TIP_TRACTION, cantilever
from verification.stress.rows import Row, Size, guarded, join_notes, judge
from verification.stress.running import FACE_SLACK, cell_size, job, method_label, method_spec, solve

def free_body_run(method: str, size: Size, rotated: bool, balanced: bool) -> Row:
    """The long bar (along x or rotated) without displacement boundaries, pulled at both end faces
    by equal and opposite tractions (balanced: it must be solved off the rigid modes with a
    warning, and any error fails; elongation between the end probes over T L / E) or at its far
    end only (``UnbalancedLoadError`` with "do not balance" is required)."""
    from engine.solvers.rigid import UnbalancedLoadError

    spec_m = method_spec(method, size)
    h = cell_size(method, size)
    label = "rotated" if rotated else "aligned"
    bar = cantilever(LONG, ROTATED if rotated else ALIGNED)
    far = {"kind": "traction", "name": "pull_far", "region": bar.end(+1, FACE_SLACK * h),
           "value": bar.direction(0, TIP_TRACTION)}
    near = {"kind": "traction", "name": "pull_near", "region": bar.end(-1, FACE_SLACK * h),
            "value": bar.direction(0, -TIP_TRACTION)}
    probes = [bar.point(1e-3 * h), bar.point(LONG - 1e-3 * h)]
    row = Row("free_body", method_label(spec_m), f"{'balanced' if balanced else 'unbalanced'}, {label} L={LONG:g}")

    def pulled(row: Row) -> None:
        s = solve(job(spec_m, h, [far, near] if balanced else [far], probes=probes), bar.mesh(), condition=balanced)
        u = s.probe()
        stretch = float((u[1] - u[0]) @ bar.frame[0])
        exact = TIP_TRACTION / E0 * (LONG - 2e-3 * h)
        warned = any("rigid-body mode" in w for w in s.warnings)
        row.values.update(stretch=stretch, exact=exact, ratio=stretch / exact, warned=warned)
        row.quantity = f"stretch/(TL/E)={stretch / exact:.4f}"
        judge(row, s)
        if warned:
            row.note = join_notes(row.note, "warned: rigid modes free, solved off them")
        else:
            row.passed = False
            row.note = join_notes("no rigid-body-mode warning", row.note)

    if balanced:
        return guarded(row, pulled, errors_allowed=False)
    return guarded(row, pulled, expect=UnbalancedLoadError, match="do not balance")


def free_body_case(method: str, size: Size) -> list[Row]:
    """Balanced along x and rotated, unbalanced rotated (see :func:`free_body_run`)."""
    return [free_body_run(method, size, False, True), free_body_run(method, size, True, True),
            free_body_run(method, size, True, False)]
