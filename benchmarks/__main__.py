"""``python -m benchmarks accuracy | scaling | stress [options]``: the issue-6 suites (see each module)."""

from __future__ import annotations

import importlib
import sys

SUITES = {"accuracy": "benchmarks.accuracy", "scaling": "benchmarks.scaling", "stress": "benchmarks.stress"}


def main(argv: list[str]) -> int:
    if not argv or argv[0] not in SUITES:
        print(f"usage: python -m benchmarks {{{' | '.join(SUITES)}}} [options]  (--help after the suite name)")
        return 2
    return importlib.import_module(SUITES[argv[0]]).main(argv[1:])


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
