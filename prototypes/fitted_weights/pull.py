"""The pulled bar with its sides inside cells (tests/test_staggered_verification.py): `pull.py on|off`."""
import sys, os
here = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, here); sys.path.insert(0, os.path.join(here, "..", "..", "tests"))
import numpy as np
import fit
import test_staggered_verification as T

if sys.argv[1] == "on":
    fit.install()
for h in (1 / 16, 1 / 32):
    corner = np.array([0.0, 0.2 * h, 0.1 * h])
    fit.MODE["centroids"] = fit.box_centroids(corner, corner + [1.0, 0.25, 0.25])
    print(h, T._cut_side_pull({"kind": "staggered", "solver": "direct"}, h), flush=True)
