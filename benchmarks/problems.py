"""The accuracy benchmark's problems live in :mod:`verification.problems` (installed with the
package, so that the tests need not import the benchmarks); this name stays for the callers not
moved yet (tests/test_dg*.py and benchmarks/dg_locking.py, owned by the DG work in flight)."""

from verification.problems import (
    BALL_CAP,
    PROBES,
    Problem,
    _shell,
    lame_problem,
    problem,
    relative_l2,
    von_mises_of,
)

__all__ = ["BALL_CAP", "PROBES", "Problem", "_shell", "lame_problem", "problem", "relative_l2", "von_mises_of"]
