"""Other shapes than the solid bar: thin walls and a through hole.

- ``thin_wall``: a closed hollow box with walls 0.3 h thick, each wall inside one cell layer or
  across a grid plane, clamped at its base, pushed sideways; over thin-walled beam theory. The
  staggered grid has one sample across a wall inside a cell layer and nothing resists its
  transverse motion: that run must stop with ``ThinFeatureError`` (a solved job fails the row).
- ``hole``: a plate with a through hole (genus 1, made with a manifold3d boolean), pulled.
"""

from __future__ import annotations

import math

import numpy as np

from verification.parts import E0, NU0, TIP_TRACTION, WIDTH, holed_plate, hollow_box
from verification.stress.rows import Row, Size, guarded, judge
from verification.stress.running import FACE_SLACK, cell_size, clamp_depth, h_label, job, method_label, method_spec, solve

def thin_wall_case(method: str, size: Size, placement: str) -> Row:
    """Closed hollow box (2 W + 0.3 h) x (2 W + 0.3 h) x (4 W + 0.3 h) with walls 0.3 h, on a pinned
    grid: every wall ``inside`` one cell layer (0.35 h .. 0.65 h of it) or ``across`` a grid plane
    (-0.15 h .. 0.15 h about it). Clamped at its base, pushed sideways on its top; top deflection
    over thin-walled beam theory (bending + shear of the two webs)."""
    from engine.grid import Grid

    spec_m = method_spec(method, size)
    h = cell_size(method, size)
    t = 0.3 * h
    b, height = 2 * WIDTH + t, 4 * WIDTH + t  # far walls sit like the near ones: b / h = n + 0.3
    start = {"inside": 0.35, "across": 0.85}[placement]  # wall start past the first cell face [h]
    mesh = hollow_box((b, b, height), t)
    n_xy, n_z = (int(math.ceil(v / h + start)) + 2 for v in (b, height))
    grid = Grid(origin=(-(1 + start) * h,) * 3, spacing=h, shape=(n_xy, n_xy, n_z))
    boundaries = [
        {"kind": "displacement", "name": "base", "region": {"box": [[-1, -1, -1], [2, 2, clamp_depth(spec_m, h)]]},
         "value": [0, 0, 0]},
        {"kind": "traction", "name": "push", "region": {"box": [[-1, -1, height - FACE_SLACK * h], [2, 2, 2]]},
         "value": [TIP_TRACTION, 0, 0]},
    ]
    probes = [[b / 2, b / 2, height - t / 2], [t / 2, b / 2, height / 2]]
    inertia = (b**4 - (b - 2 * t) ** 4) / 12
    force = TIP_TRACTION * b * b
    beam = force * height**3 / (3 * E0 * inertia) + force * height / (E0 / (2 * (1 + NU0)) * 2 * b * t)
    row = Row("thin_wall", method_label(spec_m), f"walls 0.3h {placement} a cell, {h_label(h)}")

    def body(row: Row) -> None:
        s = solve(job(spec_m, h, boundaries, probes=probes), mesh, grid=grid)
        top = float(s.probe()[0][0])
        row.values.update(top=top, beam=beam, ratio=top / beam)
        row.quantity = f"top/beam={top / beam:.3f}"
        judge(row, s)

    if method == "staggered" and placement == "inside":
        # one sample across each wall: nothing resists its transverse motion (957 zero-energy
        # motions at h = W/6, all found); the job must stop with the error that says so
        from engine.errors import ThinFeatureError

        return guarded(row, body, expect=ThinFeatureError, match="thinner than a grid cell")
    return guarded(row, body)


def hole_case(method: str, size: Size) -> Row:
    """Plate 1 x 0.5 x 0.125 m with a 0.2 m through hole (genus 1), clamped at x = 0, pulled at
    x = 1: end displacement over the holeless plate's T L / E, and the largest cell-centre sigma_xx
    over T (the net-section Kt at d / W = 0.4 is ~2.2, ~3.6 on the gross section; cell centres
    smear the peak)."""
    spec_m = method_spec(method, size)
    h = cell_size(method, size)
    L, W, T = 1.0, 2 * WIDTH, WIDTH / 2
    mesh = holed_plate((L, W, T), 0.1)
    boundaries = [
        {"kind": "displacement", "name": "clamp", "region": {"box": [[-1, -1, -1], [clamp_depth(spec_m, h), 2, 2]]},
         "value": [0, 0, 0]},
        {"kind": "traction", "name": "pull", "region": {"box": [[L - FACE_SLACK * h, -1, -1], [2, 2, 2]]},
         "value": [TIP_TRACTION, 0, 0]},
    ]
    probes = [[L - 1e-3 * h, W / 2, T / 2], [L / 2, 0.05, T / 2]]
    row = Row("hole", method_label(spec_m), f"plate with a hole, {h_label(h)}")

    def body(row: Row) -> None:
        s = solve(job(spec_m, h, boundaries, probes=probes), mesh)
        end = float(s.probe()[0][0])
        holeless = TIP_TRACTION * L / E0
        kt = float(np.abs(s.final.cells["stress"][s.material][:, 0]).max() / TIP_TRACTION)
        row.values.update(end=end, holeless=holeless, ratio=end / holeless, max_sxx_over_T=kt)
        row.quantity = f"end/(TL/E)={end / holeless:.3f} max sxx/T={kt:.2f}"
        judge(row, s)

    return guarded(row, body)
