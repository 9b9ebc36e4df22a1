"""The one place that initialises Taichi (the maintained gstaichi build).

Kernel modules import ``gstaichi`` for decorators; only :func:`init` calls ``ti.init``. Importing
this module does not initialise anything; it makes Taichi's decorators quick (kernel modules import
it first: :func:`_quick_class_check`).

Every kernel is declared ``@ti.kernel(fastcache=True)``: gstaichi then finds a compiled kernel from
a hash of its source and arguments, without running the front end that turns the kernel's Python
AST into IR (Taichi 1.7 ran it in every process to compute its cache key: most of a cold job's
extra time; docs/benchmarks.md, "Cold start"). That hash covers the kernel and the functions it
calls, not the module constants they read, so :func:`_source_keyed_fast_cache` keeps that index
per version of the engine's source.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import linecache
import os
import signal
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import gstaichi as ti  # engine/__init__.py has set its environment: no banner on stdout

from .devices import check_arch, cuda_driver_present
from .errors import BackendError
from .geometry.cache import cache_root

Arch = Literal["cpu", "cuda", "auto"]
Precision = Literal["f64", "f32"]


@dataclass(frozen=True)
class RuntimeInfo:
    """What :func:`init` chose: the backend actually running and the float precision."""

    arch: str
    precision: str
    cache_dir: str


_current: RuntimeInfo | None = None


def default_cache_dir() -> Path:
    """Taichi's offline kernel cache, under the engine's cache root."""
    return cache_root() / "gstaichi"


def init(arch: Arch = "cpu", precision: Precision = "f64", cache_dir: str | Path | None = None) -> RuntimeInfo:
    """Initialise Taichi once per process; later calls with the same settings are no-ops.

    ``auto`` is CUDA where the CUDA driver loads, else the CPU (``ti.gpu``/OpenGL probing
    segfaults on GPU-less machines; ``ti.cuda`` there falls back to the CPU with warnings). Asking for different settings
    after initialisation raises, because fields allocated under the old runtime would dangle.
    """
    global _current
    if arch not in ("cpu", "cuda", "auto"):
        raise ValueError(f"arch: expected 'cpu', 'cuda' or 'auto', got {arch!r}")
    if precision not in ("f64", "f32"):
        raise ValueError(f"precision: expected 'f64' or 'f32', got {precision!r}")
    if _current is not None:
        if _current.precision != precision or (arch != "auto" and _current.arch != arch):
            raise BackendError(
                f"solver.arch / solver.precision: Taichi already initialised with arch={_current.arch}, precision="
                f"{_current.precision}; cannot switch to arch={arch}, precision={precision} in the same process"
            )
        return _current
    check_arch(arch)  # Taichi would fall back to the CPU with a warning alone
    cache = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    cache.mkdir(parents=True, exist_ok=True)
    # Kernels compute in f64 whatever the precision: geometry must stay exact, and "f32" only
    # selects the storage of the solver's arrays (half the memory traffic).
    fp = ti.f64
    if arch == "auto":
        arch = "cuda" if cuda_driver_present() else "cpu"
    _plain_source_positions()
    _source_keyed_fast_cache()
    with contextlib.redirect_stdout(io.StringIO()):
        ti.init(
            arch=ti.cpu if arch == "cpu" else ti.cuda,
            default_fp=fp,
            offline_cache=True,
            offline_cache_file_path=str(cache),
            # f32 stores f64 results into f32 arrays on purpose; Taichi warns at every such store
            log_level=ti.WARN if precision == "f64" else ti.ERROR,
        )
    chosen = ti.lang.impl.current_cfg().arch
    if arch == "cuda" and chosen != ti.cuda:  # a driver but no usable device
        raise BackendError("solver.arch: 'cuda' was asked for, but Taichi found no usable CUDA device here; use "
                           "'auto' or 'cpu'")
    _current = RuntimeInfo(arch="cuda" if chosen == ti.cuda else "cpu", precision=precision, cache_dir=str(cache))
    return _current


def _quick_class_check() -> None:
    """Make Taichi's decorators read the line that declares a kernel's enclosing scope directly.

    Every ``@ti.kernel`` and ``@ti.func`` asks, when its module is imported, whether it is defined
    inside a class, by reading the calling frame's source line through ``inspect.getframeinfo``,
    which maps the frame to its module by scanning all of ``sys.modules`` (about a thousand modules
    in a job) for each of the engine's 175 decorators: 0.1 s of a cold job (the bundled cantilever's
    first job +2.64 -> +2.54 s, medians of three; docs/benchmarks.md, "Cold start"). The line
    itself is ``linecache``'s, the same cache ``getframeinfo`` ends in, so the answer is the same.
    A Taichi without this helper keeps its own.
    """
    from gstaichi.lang import kernel_impl

    patterns = getattr(kernel_impl, "_KERNEL_CLASS_STACKFRAME_STMT_RES", None)
    if patterns is None or not hasattr(kernel_impl, "_inside_class") or getattr(kernel_impl, "_quick_class", False):
        return

    def inside_class(level_of_class_stackframe: int) -> bool:
        try:
            frame = sys._getframe(level_of_class_stackframe)
        except ValueError:
            return False
        line = linecache.getline(frame.f_code.co_filename, frame.f_lineno, frame.f_globals).strip()
        return any(p.match(line) for p in patterns)

    kernel_impl._inside_class = inside_class
    kernel_impl._quick_class = True


_quick_class_check()


def _plain_source_positions() -> None:
    """Make Taichi's front end record a kernel statement's position as file, line and source line.

    Taichi formats every statement's position eagerly while it turns a kernel's Python AST into its
    IR: line-wrapped source with a caret line under the statement's columns, made by ``textwrap``.
    Taichi 1.7 did that in every process, even when the offline cache held the compiled kernel, and
    the formatting was a third of a cold job's extra time (the bundled cantilever: first job 4.5 s,
    3.25 s without it, the next jobs 0.6-0.7 s; docs/benchmarks.md, "Cold start"); gstaichi does it
    where its fast cache has no entry (a new kernel, a changed engine). The plain form keeps what a
    compile error needs to name the statement. The cache key does not depend on it (the cached
    kernels load unchanged). A Taichi without this method keeps its own formatting.
    """
    from gstaichi.lang.ast import ast_transformer_utils

    context = getattr(ast_transformer_utils, "ASTTransformerContext", None)
    if context is None or not hasattr(context, "get_pos_info") or getattr(context, "_plain_positions", False):
        return

    def get_pos_info(self, node) -> str:
        line = node.lineno + self.lineno_offset
        return f'File "{self.file}", line {line}, in {self.func.func.__name__}:\n{self.src[node.lineno - 1]}\n'

    context.get_pos_info = get_pos_info
    context._plain_positions = True


def _source_keyed_fast_cache() -> None:
    """Keep gstaichi's fast-cache index (source hash -> compiled kernel) in a folder named after a
    hash of every engine source file.

    The fast cache's key hashes a kernel's own source, the functions it calls and its arguments, but
    not the module constants it reads (``B``, ``TILE``, the static tables): a changed constant would
    load the kernel compiled with the old one. A new folder per source version makes any change to
    the engine run the front end once per kernel again (what every process did before); the
    compiled kernels themselves stay in the shared offline cache, keyed by their IR, so an unchanged
    kernel is not compiled again. Hashing the 75 files takes ~2 ms. A build without
    this index keeps its own.
    """
    try:
        from gstaichi.lang._fast_caching import python_side_cache, src_hasher
    except ImportError:
        return
    if getattr(src_hasher, "_engine_keyed", False):
        return
    root = Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        digest.update(path.relative_to(root).as_posix().encode())
        digest.update(path.read_bytes())
    version = digest.hexdigest()[:16]

    class EngineKeyed(python_side_cache.PythonSideCache):
        def __init__(self) -> None:
            super().__init__()
            self.cache_folder = os.path.join(self.cache_folder, version)
            os.makedirs(self.cache_folder, exist_ok=True)

    src_hasher.PythonSideCache = EngineKeyed
    src_hasher._engine_keyed = True
    # gstaichi warns at each module constant a fast-cached kernel reads; the folder's name covers
    # them, so the warning asks nothing of a user
    warnings.filterwarnings("ignore", message=r"\[PURE\.VIOLATION\]", category=UserWarning)


# How long a forked cache writer may take before it is stopped (the bundled cantilever: ~25 ms).
SAVE_TIMEOUT = 60.0


def save_kernel_cache() -> None:
    """Write the kernels compiled so far to the offline cache now, not only at a normal exit.

    A service worker stopped by a limit or a cancellation would otherwise lose what its jobs
    compiled, and its replacement would compile it again inside the next job. The writing happens
    in a forked copy of the process: gstaichi's ``dump_cache_data_to_disk`` frees the machine code
    of the kernels it writes while the process still launches them, so the next job after one that
    compiled new kernels died of SIGSEGV in the same process. The fork costs ~20-25 ms (the bundled
    cantilever). No-op before :func:`init` and where there is no fork (the kernels are then written
    at a normal exit only).
    """
    if _current is None or not hasattr(os, "fork"):
        return
    sys.stdout.flush()
    sys.stderr.flush()
    pid = os.fork()
    if pid == 0:  # the copy: write and leave at once (no atexit, no finalizers, no shared pipes touched)
        code = 0
        try:
            ti.lang.impl.get_runtime().prog.dump_cache_data_to_disk()
        except BaseException:  # a full disk, a read-only cache: the kernels compile again next time, no more
            code = 1
        os._exit(code)
    deadline = time.monotonic() + SAVE_TIMEOUT
    while os.waitpid(pid, os.WNOHANG) == (0, 0):
        if time.monotonic() > deadline:  # a lock some other thread held at the fork: give up on this save
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            return
        time.sleep(0.002)


def current() -> RuntimeInfo | None:
    """The runtime chosen by :func:`init`, or None before it ran."""
    return _current


def ensure_initialized() -> RuntimeInfo:
    """The current runtime, initialising the default (cpu, f64) if nothing ran :func:`init` yet.

    For library use (geometry without a job); jobs call :func:`init` with their settings first.
    """
    return _current if _current is not None else init("cpu", "f64")


# ----------------------------------------------------------------------------- device arrays
# The methods hold their device data in Taichi ndarrays made here, so a switch of Taichi build
# touches this module and the kernel modules only.

_TYPES = {np.float64: ti.f64, np.float32: ti.f32, np.int32: ti.i32, np.int8: ti.i8}


def solve_float() -> type:
    """The numpy float type of the solve precision (``solver.precision``)."""
    return np.float64 if ensure_initialized().precision == "f64" else np.float32


def device_zeros(shape: tuple[int, ...], dtype: type | None = None):
    """A zero Taichi ndarray of ``shape`` in numpy type ``dtype`` (default the solve precision's)."""
    return ti.ndarray(dtype=_TYPES[np.dtype(dtype or solve_float()).type], shape=tuple(shape))


def kernel_input(values: np.ndarray, dtype: type | None = None):
    """``values`` for kernels that only read them, kept beside a host array that stays: on the CPU
    backend the host array itself when it already has the type (Taichi kernels read numpy arrays
    in place there, so a device copy would only double the memory), else :func:`device_array`."""
    values = np.asarray(values)
    wanted = _stored_type(values, dtype)
    if ensure_initialized().arch == "cpu" and values.dtype == wanted and values.flags.c_contiguous:
        return values
    return device_array(values, wanted.type)


def _stored_type(values: np.ndarray, dtype: type | None) -> np.dtype:
    """The type an array of ``values`` is kept in: ``dtype``, else the solve precision for floats
    and booleans, else their own."""
    return np.dtype(dtype or (solve_float() if values.dtype.kind in "fb" else values.dtype))


def device_array(values: np.ndarray, dtype: type | None = None):
    """A Taichi ndarray holding ``values`` (float arrays in the solve precision unless ``dtype``)."""
    values = np.asarray(values)
    values = np.ascontiguousarray(values, dtype=_stored_type(values, dtype))
    out = device_zeros(values.shape, values.dtype.type)
    out.from_numpy(values)
    return out
