"""``voxelastic`` command line: validate a job, voxelize a mesh, run a job.

Bad input ends with exit code 2 and one clear line per problem on stderr, never a traceback.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

EXIT_BAD_INPUT = 2


def _error(lines: list[str] | str) -> int:
    for line in [lines] if isinstance(lines, str) else lines:
        print(f"error: {line}", file=sys.stderr)
    return EXIT_BAD_INPUT


def _read_spec(path: str):
    """The parsed job spec, or a list of error lines (file unreadable, invalid spec)."""
    from schemas import SpecError, parse_job

    try:
        return parse_job(Path(path).read_bytes())
    except OSError as exc:
        return [f"cannot read job file '{path}': {exc.strerror or exc}"]
    except SpecError as exc:
        return exc.errors


class ProgressBar:
    """One self-overwriting line on stderr: ``[#####.....]  50%  stage  detail``."""

    def __init__(self, stream=sys.stderr, width: int = 30):
        self.stream, self.width, self.start = stream, width, time.perf_counter()
        self.tty = stream.isatty()

    def __call__(self, stage: str, fraction: float, info: dict) -> None:
        filled = int(round(self.width * min(max(fraction, 0.0), 1.0)))
        detail = " ".join(f"{k}={v}" for k, v in info.items())
        line = f"[{'#' * filled}{'.' * (self.width - filled)}] {100 * fraction:3.0f}% {stage:10s} {detail}"
        line += f" ({time.perf_counter() - self.start:.1f} s)"
        self.stream.write(("\r" + line + "\x1b[K") if self.tty else line + "\n")
        self.stream.flush()

    def close(self) -> None:
        if self.tty:
            self.stream.write("\n")


def cmd_validate(args) -> int:
    spec = _read_spec(args.job)
    if isinstance(spec, list):
        return _error(spec)
    print(f"OK: {args.job} ({spec.dimension}D, method {spec.method.kind}, analysis {spec.analysis.kind})")
    return 0


def cmd_voxelize(args) -> int:
    from .errors import VoxelasticError
    from .geometry.fractions import volume_fractions
    from .geometry.loading import load_surface
    from .grid import make_grid
    from .output import write_result
    from .pipeline import Geometry, geometry_result
    from .runtime import init

    try:
        init("cpu", "f64")
        t = time.perf_counter()
        surface = load_surface(args.mesh, dimension=args.dimension, scale=args.scale)
        grid = make_grid(*surface.bounds, cell_size=args.cell_size, resolution=args.resolution, padding=args.padding)
        vf = volume_fractions(surface, grid)
        spec = {"geometry": {"mesh": Path(args.mesh).name, "scale": args.scale}, "grid": grid.to_dict(), "dimension": args.dimension}
        warnings = surface.warnings + vf.warnings
        geo = Geometry(surface, grid, fractions=vf, warnings=warnings, stage_times={"voxelize": time.perf_counter() - t})
        path = write_result(geometry_result(spec, geo, "voxelize"), args.output)
    except VoxelasticError as exc:
        return _error(str(exc))
    for w in warnings:
        print(f"warning: {w}", file=sys.stderr)
    exact = surface.enclosed_volume()
    print(
        f"{path}: {'x'.join(map(str, grid.shape))} cells of {grid.spacing:.6g} m, "
        f"{len(vf.cells.coords)} tiles stored, solid {vf.solid_volume():.9g} (mesh {exact:.9g})"
    )
    return 0


def cmd_run(args) -> int:
    from .errors import VoxelasticError
    from .geometry.cache import GeometryCache, default_directory
    from .output import write_result
    from .pipeline import run

    spec = _read_spec(args.job)
    if isinstance(spec, list):
        return _error(spec)
    if args.arch:
        spec = spec.model_copy(update={"solver": spec.solver.model_copy(update={"arch": args.arch})})
    bar = ProgressBar()
    try:
        result = run(
            spec,
            base_dir=Path(args.job).resolve().parent,
            progress=bar,
            cache=GeometryCache(None if args.no_cache else default_directory()),
        )
    except VoxelasticError as exc:  # bad input, or a method not available yet
        bar.close()
        return _error(str(exc))
    bar.close()
    path = write_result(result, args.output)
    print(f"{path}")
    return 0


def cmd_serve(args) -> int:
    from service.server import serve  # lazily: the engine does not depend on the service

    return serve(args.host, args.port, args.log_level)


def build_parser() -> argparse.ArgumentParser:
    from . import __version__

    ap = argparse.ArgumentParser(prog="voxelastic", description="Elasticity of surface meshes on voxel grids.")
    ap.add_argument("--version", action="version", version=f"voxelastic {__version__}")
    sub = ap.add_subparsers(dest="command", required=True)

    p = sub.add_parser("validate", help="check a job spec; print OK or every error with its path")
    p.add_argument("job", help="job spec (JSON)")
    p.set_defaults(func=cmd_validate)

    p = sub.add_parser("voxelize", help="exact volume fractions of a mesh on a grid, written to HDF5 (+ XDMF)")
    p.add_argument("mesh", help="mesh file (STL, OBJ, PLY, GLB, ...; SVG/DXF with --dimension 2)")
    size = p.add_mutually_exclusive_group(required=True)
    size.add_argument("--cell-size", type=float, help="cell edge h [mesh units x scale]")
    size.add_argument("--resolution", type=int, help="cells along the longest side")
    p.add_argument("--padding", type=int, default=1, help="empty cells on every side (default 1)")
    p.add_argument("--dimension", type=int, choices=(2, 3), default=3)
    p.add_argument("--scale", type=float, default=1.0, help="factor applied to the coordinates")
    p.add_argument("-o", "--output", required=True, help="result file (.h5); the .xdmf sidecar goes beside it")
    p.set_defaults(func=cmd_voxelize)

    p = sub.add_parser("run", help="run a job spec; progress on stderr")
    p.add_argument("job", help="job spec (JSON); geometry.mesh is relative to its directory")
    p.add_argument("-o", "--output", required=True, help="result file (.h5)")
    p.add_argument("--arch", choices=("cpu", "cuda", "auto"), help="override solver.arch")
    p.add_argument("--no-cache", action="store_true", help="recompute the cut-cell geometry")
    p.set_defaults(func=cmd_run)

    p = sub.add_parser("serve", help="run the job service (REST API + workers); settings from VOXELASTIC_* variables")
    p.add_argument("--host", help="bind address (default VOXELASTIC_HOST or 127.0.0.1)")
    p.add_argument("--port", type=int, help="port (default VOXELASTIC_PORT or 8000)")
    p.add_argument("--log-level", default="info", choices=("critical", "error", "warning", "info", "debug"))
    p.set_defaults(func=cmd_serve)
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    raise SystemExit(main())
