"""What compute devices this machine has, without starting Taichi (admission checks, the CLI's
``validate``): the runtime itself (``engine.runtime``) asks the same question before ``ti.init``."""

from __future__ import annotations

import ctypes

from .errors import BackendError

NO_CUDA = ("solver.arch: 'cuda' was asked for, but this machine has no CUDA driver; use 'auto' (CUDA where "
           "present, else the CPU) or 'cpu'")


def cuda_driver_present() -> bool:
    """Whether the CUDA driver library loads (what Taichi's CUDA backend needs first)."""
    try:
        ctypes.CDLL("libcuda.so.1")
    except OSError:
        return False
    return True


def check_arch(arch: str) -> None:
    """BackendError naming ``solver.arch`` when it asks for a device this machine lacks."""
    if arch == "cuda" and not cuda_driver_present():
        raise BackendError(NO_CUDA)
