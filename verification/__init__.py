"""Solids with known answers, and the stress suite's hard cases, shared by the tests and the benchmarks.

The tests import this package, never ``benchmarks`` (which is not installed); the benchmarks
import it too, so a problem is defined once:

- :mod:`verification.problems`: manufactured and closed-form problems with exact displacement and
  stress (the Lamé thick sphere, the 2D annulus, the ball), their probes and job specs.
- :mod:`verification.parts`: the stress suite's cantilever bar, hollow box and holed plate, and
  the beam-theory tips they are compared with (Timoshenko, the elastica).
- :mod:`verification.stress`: the stress suite's cases, each a function returning judged rows
  (``python -m benchmarks.stress`` runs them all and prints the table; tests/test_stress.py runs the
  cheap ones).

It sits beside ``engine`` rather than inside it: it is what the engine is checked against, it
runs the engine only through its public stages, and the engine never imports it.
"""
