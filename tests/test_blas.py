"""engine.blas: batches of tiny dense problems run on one OpenBLAS thread, and only inside."""

import numpy as np
import pytest
from threadpoolctl import threadpool_info

from engine.blas import on_one_thread, one_thread


def openblas_threads() -> list[int]:
    return [lib["num_threads"] for lib in threadpool_info() if lib["internal_api"] == "openblas"]


def test_one_thread_limits_every_openblas_and_restores_it():
    np.linalg.solve(np.eye(2), np.ones(2))  # numpy's BLAS loaded
    before = openblas_threads()
    if not before:
        pytest.skip("numpy uses no OpenBLAS here")
    with one_thread():
        assert openblas_threads() == [1] * len(before)
    assert openblas_threads() == before


def test_the_decorator_keeps_results_and_names():
    @on_one_thread
    def batched_inverse(a: np.ndarray) -> np.ndarray:
        """docstring kept"""
        assert all(n == 1 for n in openblas_threads())
        return np.linalg.solve(a, np.broadcast_to(np.eye(a.shape[-1]), a.shape))

    a = np.tril(np.random.default_rng(0).uniform(size=(50, 10, 10))) + 3 * np.eye(10)
    assert np.allclose(np.einsum("pij,pjk->pik", a, batched_inverse(a)), np.eye(10), atol=1e-12)
    assert batched_inverse.__name__ == "batched_inverse" and batched_inverse.__doc__ == "docstring kept"
