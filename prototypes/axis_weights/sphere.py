"""Thick sphere, relative L2 error at 500 probes: `sphere.py on|engine|off 0.1,0.05 free|clamped|outer`
(the cut_cell_centroids harness's sphere; ``axisw.mode`` says what each first argument runs)."""
import os
import runpy
import sys

here = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, here)
import axisw  # installs the correction before the harness's sphere imports cutstrain

axisw.mode(sys.argv[1])

os.environ.setdefault("SHEAR", "1")   # the harness's _post then slices the edge control volumes too
sys.argv = [os.path.join(here, "..", "cut_cell_centroids", "sphere.py")] + sys.argv[1:]
runpy.run_path(sys.argv[0], run_name="__main__")
