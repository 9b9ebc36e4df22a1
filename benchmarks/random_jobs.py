"""Random valid jobs through ``engine.pipeline.run``: an exception that is not a named error, or a
non-finite value in the solid's fields, is a finding.

Usage:
    .venv/bin/python -m benchmarks.random_jobs [--seed 0] [--count 60] [--dimension 3] [--precision f64]

Each job is drawn from its seed alone (``--seed`` .. ``--seed + --count - 1``), so a finding is
rerun with ``--seed N --count 1``. 3D: a box, ball, torus, thin plate, cylinder, capsule, two boxes,
an open sphere, an inverted box, two overlapping spheres (one file, not united), a doubled box
(every facet twice), a needle or a box with degenerate facets, rotated at random half the time;
staggered (auto / iterative / direct) or DG (k = 1, 2; IP or BZ; corotated one time in five).
2D: polygons (stars, annuli, rectangles, a thin strip, two squares), staggered. A clamp on one end
most of the time, else a free body with pressure loads; extra holds, tractions and pressures on
boxes, half-spaces or balls, with and without ``facing``; static, quasi-static or dynamic; random
moduli (1e3-1e11 Pa), nu from 0 to 0.4999, fields, probes (one outside), resolution 6-28 (DG 6-14).
Every job runs in this one process (Taichi is initialised once: ``--precision`` applies to all).

Prints one line per job: ``ok`` with the iterations, residual and warnings' count, ``refused:``
with the named error, or ``CRASH`` / ``BAD`` (written with its spec and traceback to ``--out``).

``--oracle hydrostatic`` keeps each draw's geometry, method and material but makes it a free body
under one pressure on its whole surface, static or quasi-static, f64, rtol 1e-12, DG with the IP
flux (Babuska-Zlamal's has no consistency term: the exact state is not its solution): sigma = -p I
exactly, whatever the shape. ``--oracle translation``: the body held at one displacement c on its
whole surface, u = c and no stress; ``--oracle shift``: held by the draw's clamp alone (its patch,
a component sometimes free) at c, no loads, u = c (0 in the free component) and no stress;
``--oracle freefall``: free under gravity alone for three backward-Euler steps, u = g t (t + dt) / 2,
v = g t, no stress; ``--oracle uniform``: a body whose facets face at most 64 directions (boxes,
prisms, polygons), free, each direction n pulled by sigma n of one random constant stress sigma:
that stress everywhere (the only exact state of a traction that is not a pressure). In
every cell, at the probes inside and on the surface the fields must be exact within
``ORACLE_TOLERANCE`` (relative to p, or to |c| and (lambda + 2 mu) |c| / 1 m), else ``WRONG``
with the largest errors (cells at least half solid and the emptier ones, ``slivers``, apart). The
corotated model's tolerance is wider (COROTATED_TOLERANCE).
"""

from __future__ import annotations

import argparse
import json
import traceback
from pathlib import Path

import numpy as np

MESHES = ["box", "sphere", "torus", "plate", "cyl", "two", "capsule", "open", "inverted", "overlap", "dupes",
          "needle", "degenerate"]
FIELDS = ["displacement", "velocity", "strain", "stress", "von_mises", "pressure"]


def mesh_3d(rng: np.random.Generator):
    import trimesh

    kind = str(rng.choice(MESHES))
    box = trimesh.creation.box
    if kind == "box":
        m = box(extents=rng.uniform(0.2, 1.5, 3))
    elif kind == "sphere":
        m = trimesh.creation.icosphere(subdivisions=3, radius=rng.uniform(0.2, 1))
    elif kind == "torus":
        m = trimesh.creation.torus(major_radius=0.6, minor_radius=rng.uniform(0.1, 0.3))
    elif kind == "plate":
        m = box(extents=[1, 1, rng.uniform(0.01, 0.1)])
    elif kind == "cyl":
        m = trimesh.creation.cylinder(radius=rng.uniform(0.05, 0.3), height=1.0)
    elif kind == "capsule":
        m = trimesh.creation.capsule(height=0.8, radius=0.2)
    elif kind == "two":
        a = box(extents=[0.4, 0.4, 0.4])
        b = a.copy()
        b.apply_translation([rng.uniform(0.3, 0.8), 0, 0])
        m = trimesh.util.concatenate([a, b])
    elif kind == "inverted":
        m = box(extents=[1, 0.3, 0.3])
        m.invert()
    elif kind == "overlap":
        a = trimesh.creation.icosphere(subdivisions=2, radius=0.4)
        b = a.copy()
        b.apply_translation([0.3, 0.1, 0])
        m = trimesh.util.concatenate([a, b])
    elif kind == "dupes":
        a = box(extents=[1, 0.4, 0.2])
        m = trimesh.Trimesh(np.vstack([a.vertices, a.vertices]),
                            np.vstack([a.faces, a.faces + len(a.vertices), a.faces[:3]]), process=False)
    elif kind == "needle":
        m = trimesh.creation.cylinder(radius=0.004, height=1.0, sections=6)
    elif kind == "degenerate":
        a = box(extents=[0.8, 0.5, 0.5])
        m = trimesh.Trimesh(np.vstack([a.vertices, a.vertices[:1]]), np.vstack([a.faces, [[0, 0, 1], [0, 8, 1]]]),
                            process=False)
    else:  # open: a sphere less one facet
        m = trimesh.creation.icosphere(subdivisions=3, radius=0.5)
        m.update_faces(np.arange(len(m.faces)) != 0)
    if rng.random() < 0.5:
        m.apply_transform(trimesh.transformations.random_rotation_matrix(rng.uniform(0, 1, 3)))
    return kind, m


def loops_2d(rng: np.random.Generator) -> tuple[str, list[np.ndarray]]:
    kind = str(rng.choice(["star", "annulus", "rect", "thin", "two"]))
    t = np.linspace(0, 2 * np.pi, int(rng.integers(5, 60)), endpoint=False)
    if kind == "star":
        r = 0.5 + rng.uniform(0, 0.3) * np.cos(int(rng.integers(2, 7)) * t)
        return kind, [np.c_[r * np.cos(t), r * np.sin(t)]]
    if kind == "annulus":
        inner = rng.uniform(0.2, 0.8)
        return kind, [np.c_[np.cos(t), np.sin(t)], (inner * np.c_[np.cos(t), np.sin(t)])[::-1]]
    if kind == "rect":
        w = rng.uniform(0.1, 2)
        return kind, [np.array([[0, 0], [w, 0], [w, 0.5], [0, 0.5]])]
    if kind == "thin":
        return kind, [np.array([[0, 0], [1, 0], [1, 0.01], [0, 0.01]])]
    square = np.array([[0, 0], [0.4, 0], [0.4, 0.4], [0, 0.4]])
    return kind, [square, square + [rng.uniform(0.3, 0.9), 0]]  # crossing below 0.4: a named refusal


def region(rng: np.random.Generator, lo: np.ndarray, hi: np.ndarray, points: np.ndarray) -> dict:
    d = len(lo)
    choice = rng.choice(["box", "half", "ball"])
    if choice == "box":
        top = lo[-1] + rng.uniform(0.02, 0.4) * (hi[-1] - lo[-1])
        return {"box": [list(lo - 1), [*(hi + 1)[:-1], top]]}
    if choice == "half":
        n = rng.normal(size=d)
        centre = (lo + hi) / 2 + 0.3 * (hi - lo) * n / np.linalg.norm(n)
        return {"halfspace": {"point": centre.tolist(), "normal": n.tolist()}}
    return {"sphere": {"center": points[rng.integers(len(points))].tolist(), "radius": float(rng.uniform(0.05, 0.5))}}


def job(rng: np.random.Generator, geometry: dict, lo: np.ndarray, hi: np.ndarray, points: np.ndarray, dg: bool,
        precision: str) -> dict:
    d = len(lo)
    free = rng.random() < 0.2
    boundaries = []
    if not free:  # a clamp across one end
        axis = int(rng.integers(d))
        top = list(hi + 1)
        top[axis] = lo[axis] + rng.uniform(0.03, 0.3) * (hi[axis] - lo[axis])
        value = [0.0] * d if rng.random() < 0.8 else [float(rng.uniform(-1e-3, 1e-3))] + [0.0] * (d - 1)
        boundaries.append({"kind": "displacement", "name": "clamp", "region": {"box": [list(lo - 1), top]},
                           "value": value})
    for i in range(int(rng.integers(0, 3))):
        kind = "pressure" if free else str(rng.choice(["displacement", "traction", "pressure"]))
        if kind == "displacement":  # a value other than the clamp's where both hold: a named refusal
            value = [float(rng.uniform(-1e-3, 1e-3)) if rng.random() < 0.5 else 0.0 if rng.random() < 0.6 else None
                     for _ in range(d)]
            value[0] = 0.0 if all(v is None for v in value) else value[0]
        elif kind == "traction":
            value = rng.uniform(-1e3, 1e3, d).tolist()
        else:
            value = float(rng.uniform(-1e3, 1e3))
        b = {"kind": kind, "name": f"b{i}", "region": region(rng, lo, hi, points), "value": value}
        if rng.random() < 0.2:
            b["facing"] = {"direction": rng.normal(size=d).tolist(), "max_angle_deg": float(rng.uniform(10, 90))}
        boundaries.append(b)
    kind = str(rng.choice(["static", "static", "quasistatic", "dynamic"]))
    analysis: dict = {"kind": kind}
    if kind != "static":
        analysis["steps"] = int(rng.integers(1, 3))
    if kind == "dynamic":
        analysis["time_step"] = float(10 ** rng.uniform(-5, -1))
    fields = [str(f) for f in rng.choice(FIELDS, size=int(rng.integers(1, 5)), replace=False)
              if f != "velocity" or kind == "dynamic"] or ["displacement"]
    if dg:
        method = {"kind": "dg", "degree": int(rng.choice([1, 2])), "flux": str(rng.choice(["ip", "bz"]))}
    else:
        method = {"kind": "staggered", "solver": str(rng.choice(["auto", "iterative", "direct"]))}
    return {"dimension": d, "geometry": geometry, "grid": {"resolution": int(rng.integers(6, 14 if dg else 28))},
            "method": method,
            "material": {"youngs_modulus": float(10 ** rng.uniform(3, 11)),
                         "poisson_ratio": float(rng.choice([0.0, 0.2, 0.3, 0.45, 0.49, 0.4999])),
                         "density": float(10 ** rng.uniform(1, 4)),
                         "model": "corotated" if dg and rng.random() < 0.2 else "linear"},
            "loads": {"gravity": rng.uniform(-10, 10, d).tolist()} if rng.random() < 0.7 and not free else {},
            "boundaries": boundaries, "analysis": analysis,
            "solver": {"rtol": 1e-8 if rng.random() < 0.7 else 1e-5, "max_iterations": 3000, "arch": "cpu",
                       "precision": precision},
            "output": {"fields": fields, "probes": [((lo + hi) / 2).tolist(), (hi + 0.5).tolist()] if rng.random() < 0.5
                       else [], "surface": bool(rng.random() < 0.5)}}


ORACLE_TOLERANCE = 1e-6  # the surface's recovery holds its conditions to ~1e-8 (their weight 1e8)
# corotated DG: sym(R^T F) - I carries the polar factor's round-off (~1e-15) against strains of p / E,
# down to 1e-9 in these draws (3e-6 of p measured)
COROTATED_TOLERANCE = 1e-4


def _oracle_job(spec: dict, boundary: dict | None, fields: list[str]) -> dict:
    """``spec`` held or loaded by ``boundary`` alone (on all of its surface unless it has a region;
    None: nothing): no gravity, static or quasi-static, f64, rtol 1e-12, DG with the IP flux."""
    analysis = {"kind": "quasistatic", "steps": 2} if spec["analysis"]["kind"] == "quasistatic" else {"kind": "static"}
    method = {**spec["method"], "flux": "ip"} if spec["method"]["kind"] == "dg" else spec["method"]
    everywhere = {"box": [[-1e3] * spec["dimension"], [1e3] * spec["dimension"]]}
    boundaries = [] if boundary is None else [{"region": everywhere, **boundary, "name": "all"}]
    return {**spec, "boundaries": boundaries, "method": method, "loads": {},
            "analysis": analysis, "solver": {**spec["solver"], "rtol": 1e-12, "precision": "f64"},
            "output": {**spec["output"], "fields": fields, "surface": True}}


def hydrostatic(spec: dict, rng: np.random.Generator, kind: str = "") -> tuple[dict, dict]:
    """A free body under pressure p on all of its surface, and what it must give: sigma = -p I
    ({field: (value [c] at load scale 1, the scale errors are relative to)})."""
    p = float(rng.uniform(-1e3, 1e3))
    d = spec["dimension"]
    want = np.concatenate([np.full(d, -p), np.zeros(3 if d == 3 else 1)])
    return _oracle_job(spec, {"kind": "pressure", "value": p}, ["stress", "pressure"]), {"stress": (want, abs(p))}


def translation(spec: dict, rng: np.random.Generator, kind: str = "") -> tuple[dict, dict]:
    """A body held at displacement c on all of its surface, and what it must give: u = c, no stress
    (relative to (lambda + 2 mu) |c| / 1 m, the stress of a strain |c| / L on the draws' bodies of
    about a metre)."""
    c = rng.uniform(-1e-3, 1e-3, spec["dimension"])
    d = spec["dimension"]
    job = _oracle_job(spec, {"kind": "displacement", "value": c.tolist()}, ["displacement", "stress"])
    return job, {"displacement": (c, float(np.linalg.norm(c))),
                 "stress": (np.zeros(6 if d == 3 else 3), _p_modulus(spec) * float(np.linalg.norm(c)))}


def shift(spec: dict, rng: np.random.Generator, kind: str = "") -> tuple[dict, dict] | None:
    """The draw's first displacement boundary alone, at one value c (a component free, null, one time
    in three), no loads: every body it holds moves by c (0 in a free component: the rigid motion
    left is the one orthogonal to the free modes), unstrained. None when the draw (of mesh ``kind``)
    holds nothing or may have two bodies (a free one would stay)."""
    held = [b for b in spec["boundaries"] if b["kind"] == "displacement"]
    if not held or kind == "two" or spec["dimension"] == 2:
        return None
    d = spec["dimension"]
    c = rng.uniform(-1e-3, 1e-3, d)
    value: list = c.tolist()
    if rng.random() < 1 / 3:
        value[int(rng.integers(d))] = None
    want = np.array([0.0 if v is None else v for v in value])
    job = _oracle_job(spec, {**held[0], "value": value}, ["displacement", "stress"])
    return job, {"displacement": (want, float(np.linalg.norm(c))),
                 "stress": (np.zeros(6), _p_modulus(spec) * float(np.linalg.norm(c)))}


def freefall(spec: dict, rng: np.random.Generator, kind: str = "") -> tuple[dict, dict]:
    """The body free under gravity g alone, three backward-Euler steps of dt from rest (rtol 1e-8): it
    falls by u(t) = g t (t + dt) / 2 and moves at v(t) = g t everywhere, unstrained."""
    d = spec["dimension"]
    g = rng.uniform(-10, 10, d)
    dt = float(10 ** rng.uniform(-4, -2))
    job = {**_oracle_job(spec, None, ["displacement", "velocity", "stress"]),
           "loads": {"gravity": g.tolist()}, "analysis": {"kind": "dynamic", "time_step": dt, "steps": 3}}
    # K on a large rigid motion rounds off at eps (c dt / h)^2 of the loads: 1e-12 met that floor in 5 of 40
    job["solver"] = {**job["solver"], "rtol": 1e-8}
    fall = float(np.linalg.norm(g)) * 3 * dt * 4 * dt / 2
    return job, {"displacement": (lambda t: g * t * (t + dt) / 2, fall),
                 "velocity": (lambda t: g * t, float(np.linalg.norm(g)) * 3 * dt),
                 # the strain of the fall over 0.1 m, about a cell: rtol 1e-8 left 1.5e-6 of (lambda + 2 mu) fall / m
                 "stress": (np.zeros(6 if d == 3 else 3), _p_modulus(spec) * fall / 0.1)}


def uniform(spec: dict, rng: np.random.Generator, kind: str = "") -> tuple[dict, dict] | None:
    """A free body whose facets face a few directions (boxes, prisms, polygons), each outward
    direction n pulled by sigma n of one random constant stress sigma (one traction boundary per
    direction, its ``facing`` within 1 degree or less than half the angle to the next direction):
    that stress everywhere. None for a curved mesh (more
    than 64 directions)."""
    d = spec["dimension"]
    directions = _facet_directions(spec)
    if directions is None:
        return None
    # strains of 1e-6 at most: the corotated model holds a constant stress only where it is linear
    a = rng.uniform(-1, 1, (d, d)) * min(1e3, 1e-6 * spec["material"]["youngs_modulus"])
    sigma = (a + a.T) / 2
    # a cone narrower than half the closest two directions' angle: no facet takes two tractions
    closest = min(np.degrees(np.arccos(np.clip(m @ n, -1, 1))) for i, m in enumerate(directions)
                  for n in directions[i + 1:])
    cone = min(1.0, 0.45 * closest)
    boundaries = [{"kind": "traction", "name": f"t{i}", "region": {"box": [[-1e3] * d, [1e3] * d]},
                   "facing": {"direction": n.tolist(), "max_angle_deg": cone}, "value": (sigma @ n).tolist()}
                  for i, n in enumerate(directions)]
    job = {**_oracle_job(spec, None, ["stress"]), "boundaries": boundaries}
    from engine.surface_stress import FEATURE_ANGLE

    if closest < FEATURE_ANGLE:
        # facets closer than the feature angle are one face at a vertex (surface_stress), whose
        # traction is the mean of theirs, sigma n_mean, short of sigma n by 1 - |n_mean| (5e-3 on a 32-gon)
        job["output"] = {**job["output"], "surface": False}
    order = [(i, i) for i in range(d)] + ([(1, 2), (0, 2), (0, 1)] if d == 3 else [(0, 1)])  # Voigt order
    return job, {"stress": (np.array([sigma[i, j] for i, j in order]), float(np.abs(sigma).max()))}


def _facet_directions(spec: dict) -> np.ndarray | None:
    """The distinct outward unit normals of the body's facets (3D mesh, oriented by trimesh) or
    edges (2D polygon, the side where the even-odd rule leaves the solid) [m, d], repeats within 1e-4
    dropped, or None beyond 64 of them."""
    if spec["dimension"] == 3:
        import trimesh

        m = trimesh.load(spec["geometry"]["mesh"])
        trimesh.repair.fix_normals(m, multibody=True)
        normals = m.face_normals[m.area_faces > 1e-12 * m.area]
    else:
        loops = [np.asarray(loop, dtype=float) for loop in spec["geometry"]["polygon"]]
        e = np.vstack([np.roll(loop, -1, axis=0) - loop for loop in loops])
        mid = np.vstack([loop + (np.roll(loop, -1, axis=0) - loop) / 2 for loop in loops])
        keep = np.linalg.norm(e, axis=1) > 0
        e, mid = e[keep], mid[keep]
        normals = np.c_[e[:, 1], -e[:, 0]] / np.linalg.norm(e, axis=1)[:, None]
        probe = mid + 1e-7 * normals
        inside = np.zeros(len(probe), dtype=bool)
        for loop in loops:  # even-odd crossings of a ray along +x
            a, b = loop, np.roll(loop, -1, axis=0)
            for (ax, ay), (bx, by) in zip(a, b):
                crosses = (ay > probe[:, 1]) != (by > probe[:, 1])
                x = ax + (probe[:, 1] - ay) * (bx - ax) / np.where(by != ay, by - ay, 1.0)
                inside ^= crosses & (probe[:, 0] < x)
        normals = np.where(inside[:, None], -normals, normals)
    kept: list[np.ndarray] = []
    for n in normals:  # 1e-4: above the float32 STL's scatter of one plane's facet normals
        if not any(np.abs(n - k).max() < 1e-4 for k in kept):
            kept.append(n)
            if len(kept) > 64:
                return None
    return np.array(kept)


def _p_modulus(spec: dict) -> float:
    """lambda + 2 mu [Pa] of the draw's material: the stress of a unit strain, what round-off in the
    displacement turns into (1667 E at nu 0.4999)."""
    e, nu = spec["material"]["youngs_modulus"], spec["material"]["poisson_ratio"]
    return e * (1 - nu) / ((1 + nu) * (1 - 2 * nu))


ORACLES = {"hydrostatic": hydrostatic, "translation": translation, "shift": shift, "freefall": freefall,
           "uniform": uniform}


def oracle_errors(r, wanted: dict) -> dict[str, float]:
    """The largest deviation of each field in ``wanted`` (an oracle's second value: {name: (value
    at load scale 1 or a function of the time, scale)}) from its value at each level, relative to its
    scale: cells at least half solid, the other cells ("slivers"), probes inside the solid, surface
    vertices."""
    half = (r.volume_fraction >= 0.5).reshape(-1)
    worst: dict[str, float] = {}
    for level in r.steps or [r.fields]:
        time = level.time if level.time is not None else 1.0  # a quasi-static level's time is its load scale
        parts = {"cells": (level.cells, half), "slivers": (level.cells, ~half), "probes": (level.probes, None),
                 "surface": (level.surface, None)}
        for name, (value, scale) in wanted.items():
            exact = value(time) if callable(value) else time * value
            for where, (arrays, keep) in parts.items():
                a = arrays.get(name)
                if a is None:
                    continue
                a = a.reshape(-1, len(exact))
                a = a if keep is None else a[keep]
                a = a[np.isfinite(a).all(axis=1)]
                if len(a):
                    err = float(np.abs(a - exact).max()) / scale
                    worst[where] = max(worst.get(where, 0.0), err)
    return worst


def draw(seed: int, dimension: int, precision: str, out: Path) -> tuple[str, dict]:
    rng = np.random.default_rng(seed)
    if dimension == 3:
        kind, m = mesh_3d(rng)
        path = out / f"mesh-{seed}.stl"
        m.export(path)
        dg = rng.random() < 0.35 and kind not in ("open", "overlap", "dupes", "degenerate")
        return kind, job(rng, {"mesh": str(path)}, *m.bounds, m.vertices, dg, precision)
    kind, loops = loops_2d(rng)
    points = np.vstack(loops)
    return kind, job(rng, {"polygon": [loop.tolist() for loop in loops]}, points.min(0), points.max(0), points, False,
                     precision)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--count", type=int, default=60)
    ap.add_argument("--dimension", type=int, choices=(2, 3), default=3)
    ap.add_argument("--precision", choices=("f64", "f32"), default="f64")
    ap.add_argument("--out", type=Path, default=Path("random-jobs"), help="meshes and findings [folder]")
    ap.add_argument("--oracle", choices=sorted(ORACLES), help="check each result against an exact state")
    args = ap.parse_args()
    from engine.errors import VoxelasticError
    from engine.geometry.cache import GeometryCache
    from engine.pipeline import Limits, run
    from schemas.job import SpecError

    args.out.mkdir(parents=True, exist_ok=True)
    for seed in range(args.seed, args.seed + args.count):
        kind, spec = draw(seed, args.dimension, args.precision, args.out)
        if args.oracle:
            made = ORACLES[args.oracle](spec, np.random.default_rng([seed, 1]), kind)
            if made is None:
                continue
            spec, wanted = made
        label = f"{seed} {kind} {spec['method']['kind']}"
        try:
            r = run(spec, cache=GeometryCache(None), limits=Limits(max_memory_bytes=8 * 2**30))
        except (VoxelasticError, SpecError) as e:
            print(label, "refused:", str(e)[:200].replace("\n", " "), flush=True)
            continue
        except Exception as e:  # the finding this script looks for
            print(label, "CRASH", type(e).__name__, str(e)[:200], flush=True)
            (args.out / f"crash-{seed}.json").write_text(json.dumps(spec))
            (args.out / f"crash-{seed}.txt").write_text(traceback.format_exc())
            continue
        solid = r.volume_fraction > 0
        bad = sorted({name for level in [r.fields, *r.steps] for name, a in level.cells.items()
                      if not np.isfinite(a[solid]).all()}
                     | {f"surface {name}" for level in [r.fields, *r.steps] for name, a in level.surface.items()
                        if not np.isfinite(a).all()})
        if args.oracle:
            worst = oracle_errors(r, wanted)
            limits = dict.fromkeys(("cells", "slivers", "probes", "surface"), ORACLE_TOLERANCE)
            if spec["material"].get("model") == "corotated":
                limits = dict.fromkeys(limits, COROTATED_TOLERANCE)
            if any(worst.get(k, 0.0) > v for k, v in limits.items()):
                bad.append("WRONG")
        if bad:
            (args.out / f"bad-{seed}.json").write_text(json.dumps(spec))
        shown = " ".join(f"{k} {v:.1e}" for k, v in worst.items()) if args.oracle else ""
        print(label, f"BAD {','.join(bad)}" if bad else "ok", r.solver.iterations, f"{r.solver.residual:.1e}",
              len(r.solver.warnings), shown, flush=True)


if __name__ == "__main__":
    main()
