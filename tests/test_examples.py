"""examples/python_api.py, the README's Python example, runs as a user runs it and its numbers are
those of beam theory."""

import re
import subprocess
import sys
from pathlib import Path

from PIL import Image

ROOT = Path(__file__).resolve().parents[1]


def test_python_api_example_runs_and_deflects_as_a_beam(tmp_path):
    out = subprocess.run([sys.executable, str(ROOT / "examples" / "python_api.py"), str(tmp_path)],
                         capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert out.returncode == 0, out.stderr[-3000:]
    tip = float(re.search(r"tip deflection (\S+) m", out.stdout).group(1))
    # Euler-Bernoulli: w = F L^3 / (3 E I) = 1.0e-2 m, F = 1000 Pa * 0.04 m^2, I = 0.2^4 / 12. Measured
    # -8.32e-3 m at x = 0.99 on this 24-cell grid (under 5 cells through the thickness, the
    # discretization is stiffer than the beam): a band that a wrong load, sign or unit leaves
    beam = 1000 * 0.04 * 1.0**3 / (3 * 1e7 * 0.2**4 / 12)
    assert -1.05 * beam < tip < -0.75 * beam, (tip, beam)
    mid = float(re.search(r"(\S+) m at mid-span", out.stdout).group(1))
    assert 0.25 < mid / tip < 0.4  # 5/16 at half span for a cantilever with a tip load
    for name in ("bar.h5", "bar.vtkhdf", "bar.solid.xdmf", "bar.surface.xdmf", "bar.png"):
        assert (tmp_path / name).is_file(), name
    assert Image.open(tmp_path / "bar.png").size == (960, 600)
