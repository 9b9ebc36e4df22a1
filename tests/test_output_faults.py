"""Result files on a disk that says no (issue 18): a write that fails for lack of space or under a
file-size limit is a plain OSError, leaves no temporary file, and the process (HDF5 included) goes
on working; it used to segfault inside HDF5. Each case runs in a subprocess with RLIMIT_FSIZE."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

SCRIPT = textwrap.dedent("""
    import errno, os, resource, sys
    from pathlib import Path
    import numpy as np
    from engine.grid import Grid
    from engine.output import FieldData, Result, write_result

    out = Path(sys.argv[1])
    limit = int(sys.argv[2])
    n = 24
    grid = Grid(origin=(0.0, 0.0, 0.0), spacing=0.1, shape=(n, n, n))
    rng = np.random.default_rng(1)  # noise: gzip cannot shrink it below the limit
    result = Result(grid=grid, method="staggered", spec={}, volume_fraction=rng.random((n, n, n)),
                    fields=FieldData(cells={"displacement": rng.random((n, n, n, 3))}))
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, hard))
    try:
        write_result(result, out / "big.h5")
    except OSError as exc:
        print("error", errno.errorcode[exc.errno], flush=True)
    print("left", sorted(p.name for p in out.iterdir()), flush=True)
    resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
    write_result(result, out / "again.h5")  # HDF5 is still usable in this process
    print("again", (out / "again.h5").stat().st_size > limit, flush=True)
""")


@pytest.mark.parametrize("limit", [0, 4096, 200_000])
def test_write_under_a_file_size_limit_is_a_plain_oserror(tmp_path, limit):
    # 0: not even the superblock fits; 4096: metadata and a variable-length string heap do not;
    # 200 kB: the first datasets fit, the displacement does not
    (tmp_path / "out").mkdir()
    run = subprocess.run([sys.executable, "-c", SCRIPT, str(tmp_path / "out"), str(limit)], cwd=ROOT,
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, f"exit {run.returncode}\n{run.stdout}\n{run.stderr[-3000:]}"
    lines = run.stdout.splitlines()
    assert lines[0] == "error EFBIG", run.stdout
    assert lines[1] == "left []", run.stdout  # the temporary file is gone
    assert lines[2] == "again True", run.stdout
