"""``voxelastic`` command line: validate a job, voxelize a mesh, run a job.

Bad input ends with exit code 2 and one clear line per problem on stderr, never a traceback.
``validate``, ``voxelize`` and ``run`` apply the same limits (facets, grid cells, memory
estimate: ``engine.pipeline.Limits``) before any work, and ``voxelize`` and ``run`` check that
the output can be written (directory writable, space for the estimated result) before it, not
after the solve. Ctrl-C ends with one line and exit code 130; the result's temporary files are
removed on the way out (``engine.output.write_result``).
"""

from __future__ import annotations

import argparse
import math
import os
import shutil
import sys
import tempfile
import time
from importlib.metadata import entry_points
from pathlib import Path

EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130  # 128 + SIGINT, what shells report for a job stopped by Ctrl-C


def _error(lines: list[str] | str) -> int:
    for line in [lines] if isinstance(lines, str) else lines:
        print(f"error: {line}", file=sys.stderr)
    return EXIT_BAD_INPUT


def _read_spec(path: str):
    """The parsed job spec, or a list of error lines (file unreadable, invalid spec)."""
    from schemas import SpecError, parse_job

    from .files import read_input

    try:
        return parse_job(read_input(path, pipe=True))
    except OSError as exc:
        return [f"cannot read job file '{path}': {exc.strerror or exc}"]
    except SpecError as exc:
        return exc.errors


def _output_problem(path: str, inputs: list[Path]) -> str | None:
    """Why a result cannot be written at ``path`` (None if it can), found before any work; ``inputs``
    (the job and mesh files) are never overwritten."""
    from .targets import replace_problem

    p = Path(path)
    if p.suffix in (".xdmf", ".vtkhdf"):
        return f"{path}: the HDF5 result needs another suffix than {p.suffix} (e.g. .h5)"
    if p.is_dir():
        return f"cannot write the result to '{path}': it is a directory"
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        return f"cannot write the result to '{path}': the directory '{parent}' does not exist"
    problem = replace_problem(p, inputs)
    if problem:
        return f"cannot write the result to '{path}': {problem}"
    try:  # the way the result is written: a temporary file beside it, renamed
        fd, probe = tempfile.mkstemp(dir=parent, prefix=f".{p.name}.", suffix=".check")
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        return f"cannot write the result to '{path}': {exc.strerror or exc} in '{parent}'"
    return None


class _NoRoom(Exception):
    """The disk holding the output has less room than the result may need."""


def _check_room(path: str, shape, fields, *, levels: int = 1, vertices: int = 0, probes: int = 0,
                spec=None) -> None:
    """_NoRoom when the directory of ``path`` has less free space than the result's estimate; with
    the job's ``spec`` the message names the fields that set the size (steps, grid, output fields)."""
    from .output import estimate_result_bytes

    need = estimate_result_bytes(shape, fields, levels=levels, surface_vertices=vertices, probes=probes)
    directory = Path(path).parent if str(Path(path).parent) else Path(".")
    free = shutil.disk_usage(directory).free
    if free >= need:
        return
    grid = "x".join(map(str, shape))
    if spec is None:
        raise _NoRoom(f"cannot write the result to '{path}': {free / 2**20:.1f} MiB free there, the result of a "
                      f"{grid} grid may need up to {need / 2**20:.1f} MiB")
    size = f"may need up to {need / 2**20:.1f} MiB, and '{directory}' has {free / 2**20:.1f} MiB free"
    shown = ", ".join(spec.output.fields) or "none"
    if spec.analysis.kind == "static":
        raise _NoRoom(f"grid: the result of a {grid} grid with output.fields [{shown}] {size}; lower "
                      "grid.resolution (or raise grid.cell_size) or output fewer fields")
    raise _NoRoom(f"analysis.steps: the result of {spec.kept_steps} steps, each holding output.fields "
                  f"[{shown}] on a {grid} grid, {size}; keep fewer steps (output.every), lower analysis.steps or "
                  "grid.resolution (or raise grid.cell_size), or output fewer fields")


def _result_levels(spec) -> int:
    """The states a job's result holds: the final one and one per kept step of a quasi-static or dynamic job."""
    return 1 + spec.kept_steps


def _admit(spec, base_dir: Path):
    """Load the job's geometry and build its grid under the limits ``run`` applies; returns
    (surface, grid). Raises the engine's errors (GeometryError, GridError) with their messages."""
    from .devices import check_arch
    from .errors import GeometryError
    from .grid import make_grid
    from .method import method_entry
    from .pipeline import Limits, load_geometry

    check_arch(spec.solver.arch)
    limits = Limits()
    surface, _ = load_geometry(spec, base_dir=base_dir)
    if len(surface.faces) > limits.max_triangles:
        raise GeometryError(f"geometry.mesh: {len(surface.faces)} facets exceed the limit of {limits.max_triangles}")
    g = spec.grid
    grid = make_grid(*surface.bounds, cell_size=g.cell_size, resolution=g.resolution, padding=g.padding,
                     max_cells=limits.max_cells)
    entry = method_entry(spec.method.kind)
    entry.check_dimension(spec.dimension)
    _check_memory(grid, spec, limits, surface)
    entry.check_job(spec, grid)
    return surface, grid


def _check_memory(grid, spec, limits, surface) -> None:
    from .errors import GridError
    from .pipeline import estimate_memory, memory_refusal

    limit = limits.max_memory_bytes
    refused = memory_refusal(estimate_memory(grid, spec.method, surface, job=spec), limit, spec, grid, surface)
    if refused is not None:
        where, what, advice = refused
        raise GridError(f"{'.'.join(where)}: {what}, over the limit of {limit / 2**30:.1f} GiB "
                        f"(VOXELASTIC_MAX_MEMORY_GB); {advice}")


class ProgressBar:
    """One self-overwriting line on stderr:
    ``[#####.....]  50% solve  step 1/3, 120 it., rel. residual 3.1e-05, ETA 4 s (2.0 s)``.

    The ETA of a solve comes from the relative residual's way down to ``rtol`` (CG's residual falls
    about geometrically, so its logarithm measures the way done), over the steps of the analysis.
    """

    def __init__(self, stream=sys.stderr, width: int = 30, rtol: float | None = None):
        self.stream, self.width, self.start = stream, width, time.perf_counter()
        self.tty = stream.isatty()
        self.rtol = rtol
        self.solve_start: float | None = None

    def _eta(self, stage: str, info: dict) -> float | None:
        """Seconds left in the solve [s], or None when nothing can be said yet."""
        if stage != "solve" or self.rtol is None or not 0 < self.rtol < 1:
            return None
        now = time.perf_counter()
        if self.solve_start is None:
            self.solve_start = now
        residual = info.get("residual")
        if residual is None or not residual > 0:
            return None
        way = min(max(math.log(residual) / math.log(self.rtol), 0.0), 1.0)
        done = (info.get("step", 1) - 1 + way) / max(info.get("steps", 1), 1)
        elapsed = now - self.solve_start
        if done <= 0.02 or elapsed < 0.2:
            return None
        return elapsed * (1 - done) / done

    @staticmethod
    def _detail(info: dict) -> str:
        parts = [info["part"]] if "part" in info else []
        if "step" in info and "steps" in info:
            parts.append(f"step {info['step']}/{info['steps']}")
        if "iterations" in info:
            parts.append(f"{info['iterations']} it.")
        if info.get("residual") is not None:
            parts.append(f"rel. residual {info['residual']:.1e}")
        if "shape" in info:
            parts.append("grid " + "x".join(map(str, info["shape"])))
        if info.get("cache_hit"):
            parts.append("cached")
        return ", ".join(parts)

    def __call__(self, stage: str, fraction: float, info: dict) -> None:
        if not self.tty and stage == "geometry":
            return  # a log gets lines from the grid on: a job refused by the checks stays one line
        filled = int(round(self.width * min(max(fraction, 0.0), 1.0)))
        detail = self._detail(info)
        eta = self._eta(stage, info)
        if eta is not None:
            detail += f", ETA {eta:.0f} s"
        line = f"[{'#' * filled}{'.' * (self.width - filled)}] {100 * fraction:3.0f}% {stage:10s} {detail}"
        line += f" ({time.perf_counter() - self.start:.1f} s)"
        self.stream.write(("\r" + line + "\x1b[K") if self.tty else line + "\n")
        self.stream.flush()

    def close(self, failed: bool = False) -> None:
        if self.tty:  # after a failure the bar goes: the error is the one line left
            self.stream.write("\r\x1b[K" if failed else "\n")
            self.stream.flush()


def cmd_validate(args) -> int:
    from .errors import VoxelasticError
    from .pipeline import check_boundaries

    spec = _read_spec(args.job)
    if isinstance(spec, list):
        return _error(spec)
    if args.output:
        mesh = spec.geometry.mesh
        inputs = [Path(args.job)] + ([Path(args.job).resolve().parent / mesh] if mesh else [])
        problem = _output_problem(args.output, inputs)
        if problem:
            return _error(problem)
    try:  # what run checks before any work: the mesh, its facets, the grid and its memory estimate
        surface, grid = _admit(spec, Path(args.job).resolve().parent)
        # and the room for the result where run would write it (-o; by default here)
        _check_room(args.output or "result.h5", grid.shape, spec.output.fields, levels=_result_levels(spec),
                    probes=len(spec.output.probes), spec=spec)
        notes = check_boundaries(spec, surface)
    except (VoxelasticError, _NoRoom) as exc:
        return _error(str(exc))
    for note in notes:
        print(f"warning: {note}", file=sys.stderr)
    print(f"OK: {args.job} ({spec.dimension}D, method {spec.method.kind}, analysis {spec.analysis.kind}, "
          f"{len(surface.faces)} facets, grid {'x'.join(map(str, grid.shape))})")
    return 0


def cmd_voxelize(args) -> int:
    from .errors import GridError, VoxelasticError
    from .geometry.fractions import volume_fractions
    from .geometry.loading import load_surface
    from .grid import make_grid
    from .method import METHODS
    from .output import write_result
    from .pipeline import Geometry, Limits, geometry_result
    from .runtime import init

    problem = _output_problem(args.output, [Path(args.mesh)])
    if problem:
        return _error(problem)
    try:
        t = time.perf_counter()
        surface = load_surface(args.mesh, dimension=args.dimension, scale=args.scale)
        limits = Limits()
        if len(surface.faces) > limits.max_triangles:
            return _error(f"{args.mesh}: {len(surface.faces)} facets exceed the limit of {limits.max_triangles}")
        grid = make_grid(*surface.bounds, cell_size=args.cell_size, resolution=args.resolution, padding=args.padding,
                         max_cells=limits.max_cells)
        # what runs here is the volume-fraction stage: the estimate of a method built on it
        entry = next(m for m in METHODS.values() if m.geometry == "fractions")
        need = entry.estimate_memory(grid, None, surface=surface)
        if need > limits.max_memory_bytes:
            raise GridError(f"{args.mesh}: a {'x'.join(map(str, grid.shape))} grid needs about {need / 2**30:.1f} GiB, "
                            f"over the limit of {limits.max_memory_bytes / 2**30:.1f} GiB (VOXELASTIC_MAX_MEMORY_GB); "
                            "increase the cell size or lower the resolution")
        _check_room(args.output, grid.shape, [], vertices=len(surface.vertices))
        init("cpu", "f64")
        vf = volume_fractions(surface, grid)
        spec = {"geometry": {"mesh": Path(args.mesh).name, "scale": args.scale}, "grid": grid.to_dict(), "dimension": args.dimension}
        warnings = surface.warnings + vf.warnings
        geo = Geometry(surface, grid, fractions=vf, warnings=warnings, stage_times={"voxelize": time.perf_counter() - t})
        path = write_result(geometry_result(spec, geo, "voxelize"), args.output)
    except (VoxelasticError, _NoRoom) as exc:
        return _error(str(exc))
    except OSError as exc:  # the disk said no while writing (it had room when checked)
        return _error(f"cannot write the result to '{args.output}': {exc.strerror or exc}")
    for w in warnings:
        print(f"warning: {w}", file=sys.stderr)
    exact = surface.enclosed_volume()
    print(
        f"{path}: {'x'.join(map(str, grid.shape))} cells of {grid.spacing:.6g} m, "
        f"{len(vf.cells.coords)} tiles stored, solid {vf.solid_volume():.9g} (mesh {exact:.9g})"
    )
    return 0


def _print_warnings(warnings: list[str]) -> None:
    """Each warning once on stderr (they are also in the result's /solver attributes)."""
    for w in dict.fromkeys(warnings):
        print(f"warning: {w}", file=sys.stderr)


def cmd_run(args) -> int:
    from .errors import VoxelasticError
    from .geometry.cache import GeometryCache, default_directory
    from .output import outside_probes_warning, write_result
    from .pipeline import run

    spec = _read_spec(args.job)
    if isinstance(spec, list):
        return _error(spec)
    mesh = spec.geometry.mesh
    inputs = [Path(args.job)] + ([Path(args.job).resolve().parent / mesh] if mesh else [])
    problem = _output_problem(args.output, inputs)
    if problem:
        return _error(problem)
    if args.arch:
        spec = spec.model_copy(update={"solver": spec.solver.model_copy(update={"arch": args.arch})})
    bar = ProgressBar(rtol=spec.solver.rtol)

    def progress(stage: str, fraction: float, info: dict) -> None:
        if stage == "grid":  # the grid is known, nothing large is allocated yet: is there room?
            _check_room(args.output, info["shape"], spec.output.fields, levels=_result_levels(spec),
                        probes=len(spec.output.probes), spec=spec)
        bar(stage, fraction, info)

    try:
        result = run(
            spec,
            base_dir=Path(args.job).resolve().parent,
            progress=progress,
            cache=GeometryCache(None if args.no_cache else default_directory()),
        )
        note = outside_probes_warning(result)
        if note:
            if result.solver is not None:
                result.solver.warnings.append(note)
        bar.close()
        path = write_result(result, args.output)
    except (VoxelasticError, _NoRoom) as exc:  # bad input, a limit, a method not available yet, no room
        bar.close(failed=True)
        _print_warnings(getattr(exc, "warnings", []))  # what setup noticed often explains the failure
        return _error(str(exc))
    except OSError as exc:  # the disk said no while writing (it had room when checked)
        bar.close(failed=True)
        return _error(f"cannot write the result to '{args.output}': {exc.strerror or exc}")
    _print_warnings(result.solver.warnings if result.solver is not None else [note] if note else [])
    from .peaks import peaks

    for place, peak in peaks(result).items():
        at = ", ".join(f"{v:.4g}" for v in peak.location)
        if peak.time is None:
            when = ""
        elif spec.analysis.kind == "quasistatic":  # its steps' "time" is the load factor k / n
            when = f" at load factor {peak.time:.4g}"
        else:
            when = f" at t = {peak.time:.4g} s"
        print(f"peak von Mises {peak.value:.4g} Pa in the {place} at ({at}) m{when}", file=sys.stderr)
    print(f"{path}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    from . import __version__

    ap = argparse.ArgumentParser(prog="voxelastic", description="Elasticity of surface meshes on voxel grids.")
    ap.add_argument("--version", action="version", version=f"voxelastic {__version__}")
    sub = ap.add_subparsers(dest="command", required=True)

    p = sub.add_parser("validate", help="check a job spec; print OK or every error with its path")
    p.add_argument("job", help="job spec (JSON)")
    p.add_argument("-o", "--output", help="the result file run would write: its directory must have room for the "
                                          "result (default: the current directory)")
    p.set_defaults(func=cmd_validate)

    p = sub.add_parser("voxelize", help="exact volume fractions of a mesh on a grid, written to HDF5 (+ XDMF)")
    p.add_argument("mesh", help="mesh file (STL, OBJ, PLY, GLB, ...; SVG/DXF with --dimension 2)")
    size = p.add_mutually_exclusive_group(required=True)
    size.add_argument("--cell-size", type=float, help="cell edge h [mesh units x scale]")
    size.add_argument("--resolution", type=int, help="cells along the longest side")
    p.add_argument("--padding", type=int, default=1, help="empty cells on every side (default 1)")
    p.add_argument("--dimension", type=int, choices=(2, 3), default=3)
    p.add_argument("--scale", type=float, default=1.0, help="factor applied to the coordinates")
    p.add_argument("-o", "--output", required=True, help="result file (.h5); the viewer files (.xdmf, .solid.xdmf, .surface.xdmf, .vtkhdf) go beside it")
    p.set_defaults(func=cmd_voxelize)

    p = sub.add_parser("run", help="run a job spec; progress on stderr")
    p.add_argument("job", help="job spec (JSON); geometry.mesh is relative to its directory")
    p.add_argument("-o", "--output", required=True, help="result file (.h5)")
    p.add_argument("--arch", choices=("cpu", "cuda", "auto"), help="override solver.arch")
    p.add_argument("--no-cache", action="store_true", help="recompute the cut-cell geometry")
    p.set_defaults(func=cmd_run)

    # commands of installed packages (the service's `serve`): the engine imports none of them
    for entry in entry_points(group="voxelastic.commands"):
        entry.load()(sub)
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except KeyboardInterrupt:
        # temporary files went with the unwinding (write_result and the geometry cache remove theirs)
        print(("\r\x1b[K" if sys.stderr.isatty() else "") + "interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    raise SystemExit(main())
