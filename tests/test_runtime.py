"""Taichi is initialised only by engine.runtime.init, once per process, with the asked settings."""

import subprocess
import sys
import textwrap

import pytest

from engine.devices import cuda_driver_present as runtime_cuda_present


def run_py(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, timeout=120)


def test_importing_the_package_never_initialises_taichi():
    out = run_py(
        """
        import engine, engine.grid, engine.blocks, engine.pipeline, engine.output, engine.cli
        import engine.geometry.fractions, engine.geometry.kernels, schemas
        import gstaichi.lang.impl as impl
        print(impl.get_runtime()._prog is None)  # gstaichi: .prog raises before ti.init
        """
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "True"


def test_init_once_with_precision_and_refuses_a_switch():
    out = run_py(
        """
        import gstaichi as ti
        from engine import runtime
        info = runtime.init("auto", "f32")
        assert runtime.init("auto", "f32") is info
        # kernels always compute in f64 (exact geometry); f32 is the solver's storage
        print(info.arch, info.precision, ti.lang.impl.get_runtime().default_fp == ti.f64)
        try:
            runtime.init("cpu", "f64")
        except RuntimeError as exc:
            print("refused:", "cannot switch" in str(exc))
        """
    )
    assert out.returncode == 0, out.stderr
    lines = out.stdout.strip().splitlines()
    assert lines[0].split()[1:] == ["f32", "True"]
    assert lines[0].split()[0] in ("cpu", "cuda")
    assert lines[1] == "refused: True"
    assert "Taichi]" not in out.stdout  # stdout stays clean for the CLI (no "[GsTaichi] version" banner)


def test_cuda_asked_for_where_there_is_none_is_an_error_naming_the_field():
    """Taichi falls back to the CPU with a log line alone; a job that asks for CUDA must hear it has none."""
    if runtime_cuda_present():
        pytest.skip("this machine has a CUDA driver")
    out = run_py(
        """
        from engine import runtime
        from engine.errors import VoxelasticError
        try:
            runtime.init("cuda", "f64")
        except VoxelasticError as exc:
            print(exc)
        print(runtime.current())
        """
    )
    assert out.returncode == 0, out.stderr
    lines = out.stdout.strip().splitlines()
    assert lines[0].startswith("solver.arch: 'cuda' was asked for, but this machine has no CUDA driver"), out.stdout
    assert lines[1] == "None"


def test_a_kernel_compile_error_still_names_its_file_line_and_statement(tmp_path):
    """init() replaces Taichi's eager caret formatting of source positions (a third of a cold job's
    extra time) by file, line and source line: a compile error must still point at the statement."""
    module = tmp_path / "broken_kernel.py"
    module.write_text(textwrap.dedent(
        """
        import gstaichi as ti

        @ti.kernel
        def broken(x: ti.types.ndarray()):
            for i in x:
                x[i] = undefined_name * 2.0
        """
    ))
    out = run_py(
        f"""
        import sys, numpy as np
        sys.path.insert(0, {str(tmp_path)!r})
        from engine import runtime
        runtime.init("cpu", "f64")
        import broken_kernel
        try:
            broken_kernel.broken(np.zeros(3))
        except Exception as exc:
            print(str(exc))
        """
    )
    assert out.returncode == 0, out.stderr
    assert 'broken_kernel.py", line 7, in broken' in out.stdout, out.stdout
    assert "x[i] = undefined_name * 2.0" in out.stdout, out.stdout
    assert "undefined_name" in out.stdout.split("x[i] =")[-1], out.stdout


def test_kernels_in_and_out_of_classes_are_told_apart_as_taichi_does(tmp_path):
    """Importing the runtime swaps Taichi's class check (inspect.getframeinfo, a scan of every
    module per decorator) for a read of the same line through linecache: a kernel in a
    data-oriented class is still a class kernel (it takes self), a module-level one is not, and
    both run."""
    module = tmp_path / "placed_kernels.py"
    module.write_text(textwrap.dedent(
        """
        import gstaichi as ti

        @ti.kernel
        def plain(x: ti.types.ndarray()):
            for i in x:
                x[i] = 2.0

        @ti.data_oriented
        class Scaler:
            def __init__(self, factor):
                self.factor = factor

            @ti.kernel
            def scale(self, x: ti.types.ndarray()):
                for i in x:
                    x[i] *= self.factor
        """
    ))
    out = run_py(
        f"""
        import sys, numpy as np
        sys.path.insert(0, {str(tmp_path)!r})
        from engine import runtime
        from gstaichi.lang import kernel_impl
        print("patched", kernel_impl._inside_class.__module__)
        runtime.init("cpu", "f64")
        import placed_kernels as pk
        x = np.zeros(3)
        pk.plain(x)
        pk.Scaler(3.0).scale(x)
        print("class kernel", pk.Scaler.scale._is_classkernel, "plain", pk.plain._is_classkernel, x.tolist())
        """
    )
    assert out.returncode == 0, out.stderr
    assert "patched engine.runtime" in out.stdout, out.stdout
    assert "class kernel True plain False [6.0, 6.0, 6.0]" in out.stdout, out.stdout


def test_a_second_process_loads_kernels_by_their_source_and_a_killed_one_keeps_what_it_saved(tmp_path):
    """Kernels are fast-cached by their source (no front end in a fresh process), and
    save_kernel_cache writes the compiled kernels at once: a process killed after it (a service
    worker stopped by a limit) leaves them to the next one."""
    module = tmp_path / "cached_kernels.py"
    module.write_text(textwrap.dedent(
        """
        import gstaichi as ti

        @ti.kernel(fastcache=True)
        def double(x: ti.types.ndarray()):
            for i in x:
                x[i] = 2.0 * x[i] + 1.0
        """
    ))
    cache = tmp_path / "cache"
    script = f"""
        import os, sys, numpy as np
        sys.path.insert(0, {str(tmp_path)!r})
        from engine import runtime
        runtime.init("cpu", "f64", cache_dir={str(cache)!r})
        import cached_kernels as ck
        x = np.arange(3.0)
        ck.double(x)
        print("loaded", ck.double._primal.src_ll_cache_observations.cache_loaded, x.tolist(), flush=True)
        runtime.save_kernel_cache()
        ck.double(x)  # a kernel written to the cache still runs (an in-process dump freed its code: SIGSEGV)
        assert x.tolist() == [3.0, 7.0, 11.0], x
        os.kill(os.getpid(), 9)
        """
    first, second = run_py(script), run_py(script)
    assert first.returncode == second.returncode == -9, (first.stderr, second.stderr)
    assert first.stdout.strip() == "loaded False [1.0, 3.0, 5.0]", first.stdout + first.stderr
    assert second.stdout.strip() == "loaded True [1.0, 3.0, 5.0]", second.stdout + second.stderr
