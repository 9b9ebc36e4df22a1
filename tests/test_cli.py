"""The voxelastic command line, run as a real subprocess: exit codes, stdout/stderr, files."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from engine.output import read_result

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "cantilever.json"


def cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "engine.cli", *map(str, args)], capture_output=True, text=True, cwd=cwd, timeout=300)


def test_validate_ok_and_every_error_with_its_path(tmp_path):
    ok = cli("validate", EXAMPLE)
    assert ok.returncode == 0 and ok.stdout.startswith("OK")
    spec = json.loads(EXAMPLE.read_text())
    spec["material"]["poisson_ratio"] = 0.5
    spec["grid"]["padding"] = -1
    spec["loads"]["gravity"] = [0, 0]
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(spec))
    out = cli("validate", bad)
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert any(line.startswith("error: material.poisson_ratio:") for line in lines)
    assert any(line.startswith("error: grid.padding:") for line in lines)
    assert "error: loads.gravity: expected 3 components (dimension 3), got 2" in lines
    assert len(lines) == 3
    assert "Traceback" not in out.stderr


def test_voxelize_writes_exact_fractions_and_the_surface(tmp_path):
    out = cli("voxelize", ROOT / "examples" / "cantilever.stl", "--cell-size", "0.03", "-o", tmp_path / "bar.h5")
    assert out.returncode == 0, out.stderr
    result = read_result(tmp_path / "bar.h5")
    assert (tmp_path / "bar.xdmf").exists()
    volume = result.volume_fraction.sum() * result.grid.spacing**3
    assert abs(volume - 0.04) < 1e-14
    assert result.surface_faces.shape == (12, 3)
    assert result.method == "voxelize"
    assert np.all((result.volume_fraction >= 0) & (result.volume_fraction <= 1))


def test_run_writes_the_result_of_the_example(tmp_path):
    job = tmp_path / "job.json"
    shutil.copy(EXAMPLE, job)
    shutil.copy(ROOT / "examples" / "cantilever.stl", tmp_path / "cantilever.stl")
    out = cli("run", job, "-o", tmp_path / "out.h5", "--no-cache")
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().endswith("out.h5")
    result = read_result(tmp_path / "out.h5")
    assert result.fields.probes["displacement"][0, 2] < -0.03
    assert result.solver.iterations > 0


@pytest.mark.parametrize(
    "mesh_text, reason",
    [
        ("this is not a mesh", "error: geometry.mesh: cannot read 'broken.stl'"),
        ("", "error: geometry.mesh: cannot read 'broken.stl'"),
    ],
)
def test_bad_mesh_is_one_clear_line(tmp_path, mesh_text, reason):
    mesh = tmp_path / "broken.stl"
    mesh.write_text(mesh_text)
    out = cli("voxelize", mesh, "--resolution", "8", "-o", tmp_path / "x.h5")
    assert out.returncode == 2
    assert "Traceback" not in out.stderr
    assert reason in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1


def test_missing_job_file_and_missing_mesh(tmp_path):
    out = cli("run", tmp_path / "nope.json", "-o", tmp_path / "x.h5")
    assert out.returncode == 2 and "cannot read job file" in out.stderr
    job = tmp_path / "job.json"
    shutil.copy(EXAMPLE, job)  # refers to cantilever.stl, absent here
    out = cli("run", job, "-o", tmp_path / "x.h5")
    assert out.returncode == 2 and "geometry.mesh: cannot read" in out.stderr


def test_voxelize_an_open_mesh_reports_the_fallback(tmp_path):
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    keep = sphere.triangles_center[:, 2] < 0.9  # cut off a cap: a hole too big to fill
    open_mesh = trimesh.Trimesh(sphere.vertices, sphere.faces[keep], process=False)
    path = tmp_path / "open.stl"
    open_mesh.export(path)
    out = cli("voxelize", path, "--resolution", "16", "-o", tmp_path / "open.h5")
    assert out.returncode == 0, out.stderr
    assert "warning: the surface is not closed" in out.stderr
    assert "winding number" in out.stderr
    result = read_result(tmp_path / "open.h5")
    volume = result.volume_fraction.sum() * result.grid.spacing**3
    full = trimesh.creation.icosphere(subdivisions=3, radius=1.0).volume
    cap = np.pi * 0.1**2 * (3 - 0.1) / 3  # spherical cap above z = 0.9
    # the winding number carves roughly the missing cap out of the ball, no more, no less
    assert full - 1.5 * cap < volume < full - 0.5 * cap
    assert any("winding number" in w for w in result.solver.warnings)


def test_run_prints_the_warnings_and_with_an_error_those_of_the_setup(tmp_path):
    """`run` printed only the outside-probe note: a repaired mesh or a thin solid was said only in the
    result's attributes, and when the job failed, not at all."""
    import trimesh

    box = trimesh.creation.box(bounds=[[0, -0.1, -0.1], [1, 0.1, 0.1]])
    box.invert()  # every face inside out: loading turns them and says so
    box.export(tmp_path / "bar.stl")
    spec = {"dimension": 3, "geometry": {"mesh": "bar.stl"}, "grid": {"resolution": 12},
            "material": {"youngs_modulus": 1e7, "poisson_ratio": 0.3, "density": 1000}, "loads": {"gravity": [0, 0, -9.81]},
            "boundaries": [{"kind": "displacement", "name": "clamp", "region": {"box": [[-1, -1, -1], [0.01, 1, 1]]},
                            "value": [0, 0, 0]}]}
    (tmp_path / "job.json").write_text(json.dumps(spec))
    done = subprocess.run([sys.executable, "-m", "engine.cli", "run", str(tmp_path / "job.json"), "-o", str(tmp_path / "r.h5")],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "warning: inverted all faces" in done.stderr and "warning: the solid is thin for this grid" in done.stderr
    spec["boundaries"] = []  # a free body under gravity: refused, after the same warnings
    (tmp_path / "job.json").write_text(json.dumps(spec))
    failed = subprocess.run([sys.executable, "-m", "engine.cli", "run", str(tmp_path / "job.json"), "-o", str(tmp_path / "s.h5")],
                            capture_output=True, text=True, timeout=600)
    assert failed.returncode == 2 and "error: " in failed.stderr and "warning: inverted all faces" in failed.stderr
