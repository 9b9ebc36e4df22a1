"""The CLI's checks before any work, Ctrl-C and probe warnings (issue 18 item 9), as real
subprocesses: the same limits in validate / voxelize / run (exit 2, one line), an unwritable
output found before the solve, Ctrl-C as one line with exit 130 and no temporary files left, probes
outside the solid named in a warning, no note about STL's merged corners; text meshes with any line
ends, a binary STL cut short and polygon errors at geometry.polygon."""

from __future__ import annotations

import json
import os
import shutil
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest

from engine.output import read_result, write_result

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "cantilever.json"
STL = ROOT / "examples" / "cantilever.stl"


def cli(*args, cwd=None, timeout=300):
    return subprocess.run([sys.executable, "-m", "engine.cli", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, timeout=timeout)


def job(tmp_path: Path, **changes) -> Path:
    spec = json.loads(EXAMPLE.read_text())
    for key, value in changes.items():
        spec[key] = value
    shutil.copy(STL, tmp_path / "cantilever.stl")
    path = tmp_path / "job.json"
    path.write_text(json.dumps(spec))
    return path


def one_error_line(out: subprocess.CompletedProcess) -> str:
    assert out.returncode == 2, (out.returncode, out.stderr[-2000:])
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), out.stderr[-2000:]
    return lines[0]


def test_the_same_grid_limit_in_validate_voxelize_and_run(tmp_path):
    # 1 um cells on the 1 m bar: 4e16 cells (voxelize used to try a 1.16 TiB allocation)
    huge = job(tmp_path, grid={"cell_size": 1e-6, "padding": 1})
    t = time.perf_counter()
    validate = one_error_line(cli("validate", huge))
    run = one_error_line(cli("run", huge, "-o", tmp_path / "r.h5"))
    voxelize = one_error_line(cli("voxelize", STL, "--cell-size", "1e-6", "-o", tmp_path / "v.h5"))
    assert time.perf_counter() - t < 60
    assert "4e+16 cells exceeds the limit" in validate
    assert validate == run == voxelize
    assert not list(tmp_path.glob("*.h5")) and not list(tmp_path.glob(".*"))


def test_validate_checks_what_run_checks_and_says_ok_otherwise(tmp_path):
    dg = job(tmp_path, method={"kind": "dg", "degree": 2}, grid={"resolution": 400, "padding": 1})
    line = one_error_line(cli("validate", dg))  # a memory estimate far over the limit
    assert "GiB for method 'dg'" in line and "over the limit" in line
    ok = cli("validate", job(tmp_path))
    assert ok.returncode == 0 and ok.stdout.startswith("OK") and "grid 34x9x9" in ok.stdout, ok.stderr
    (tmp_path / "cantilever.stl").unlink()
    assert "geometry.mesh: cannot read" in one_error_line(cli("validate", tmp_path / "job.json"))


def test_validate_refuses_the_boundaries_run_would_refuse(tmp_path):
    spec = json.loads(EXAMPLE.read_text())
    clamp = spec["boundaries"][0]
    pull = {**clamp, "name": "pull", "value": [0.001, None, None]}  # the clamp's own patch, another u_x
    far = {**clamp, "name": "far", "region": {"box": [[5, 5, 5], [6, 6, 6]]}}
    for extra, reason in ((pull, "clamp and pull: both prescribe u_x on the same"),
                          (far, "far: the region holds no part of the mesh surface")):
        line = one_error_line(cli("validate", job(tmp_path, boundaries=[*spec["boundaries"], extra])))
        assert reason in line, line


@pytest.mark.parametrize("where", ["missing-dir", "directory", "proc"])
def test_an_unwritable_output_is_found_before_any_work(tmp_path, where):
    target = {"missing-dir": tmp_path / "no" / "such" / "out.h5", "directory": tmp_path,
              "proc": Path("/proc/voxelastic-out.h5")}[where]
    big = job(tmp_path, grid={"resolution": 96, "padding": 1})  # seconds of work if it started
    for args in (("run", big, "-o", target), ("voxelize", STL, "--resolution", "96", "-o", target)):
        t = time.perf_counter()
        line = one_error_line(cli(*args))
        assert "cannot write the result to" in line, line
        assert time.perf_counter() - t < 5  # before the mesh is even read, let alone solved


def test_a_result_never_replaces_an_input_a_device_or_a_file_that_is_not_a_result(tmp_path):
    spec = job(tmp_path, grid={"resolution": 8, "padding": 1})
    os.mkfifo(tmp_path / "pipe.h5")
    (tmp_path / "notes.h5").write_text("mine")
    (tmp_path / "side.xdmf").mkdir()  # a side file's name taken by a directory
    inputs = {p: p.read_bytes() for p in (spec, tmp_path / "cantilever.stl")}
    cases = {tmp_path / "cantilever.stl": "is the job's own input", spec: "is the job's own input",
             tmp_path / "pipe.h5": "exists and is not a regular file",
             tmp_path / "notes.h5": "exists and is not an HDF5 file", tmp_path / "side.h5": "side.xdmf' exists and is not"}
    for target, reason in cases.items():
        line = one_error_line(cli("run", spec, "-o", target))
        assert reason in line, line
    assert reason in one_error_line(cli("voxelize", STL, "--resolution", "8", "-o", tmp_path / "side.h5"))
    assert "own input" in one_error_line(cli("voxelize", tmp_path / "cantilever.stl", "--resolution", "8",
                                             "-o", tmp_path / "cantilever.stl"))
    assert all(p.read_bytes() == data for p, data in inputs.items()) and (tmp_path / "notes.h5").read_text() == "mine"
    assert stat.S_ISFIFO((tmp_path / "pipe.h5").lstat().st_mode)
    assert cli("run", spec, "-o", tmp_path / "r.h5").returncode == 0
    assert cli("run", spec, "-o", tmp_path / "r.h5").returncode == 0  # an earlier result is replaced
    with pytest.raises(FileExistsError, match="not an HDF5 file"):  # the Python API's writer too
        write_result(read_result(tmp_path / "r.h5"), tmp_path / "notes.h5")


def test_ctrl_c_is_one_line_exit_130_and_no_temporary_files(tmp_path):
    long = job(tmp_path, grid={"resolution": 48, "padding": 1},
               analysis={"kind": "dynamic", "time_step": 1e-3, "steps": 400})
    out = tmp_path / "out"
    out.mkdir()
    # a pytest started in the background (`... &` in a script) has SIGINT ignored, and the child would
    # inherit that: the CLI gets the disposition a terminal gives it
    proc = subprocess.Popen([sys.executable, "-m", "engine.cli", "run", str(long), "-o", str(out / "r.h5"),
                             "--no-cache"], stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    seen = []
    for line in proc.stderr:  # until the solve runs
        seen.append(line)
        if " solve " in line:
            break
    proc.send_signal(signal.SIGINT)
    rest = proc.stderr.read()
    code = proc.wait(60)
    assert code == 130, (code, rest[-3000:])
    assert rest.strip().splitlines() == ["interrupted"] or rest.strip().splitlines()[-1] == "interrupted", rest
    assert "Traceback" not in rest
    assert list(out.iterdir()) == []


def test_probes_outside_the_solid_are_a_warning_saying_how_many_and_where(tmp_path):
    spec = job(tmp_path, grid={"resolution": 16, "padding": 2})
    data = json.loads(spec.read_text())
    # inside the bar; beyond its free end (x > 1) and beside it (y > 0.1), both still in the grid
    data["output"]["probes"] = [[0.5, 0, 0], [1.08, 0, 0], [0.5, 0.16, 0]]
    spec.write_text(json.dumps(data))
    out = cli("run", spec, "-o", tmp_path / "r.h5", "--no-cache")
    assert out.returncode == 0, out.stderr
    warnings = [line for line in out.stderr.splitlines() if line.startswith("warning:") and "probes" in line]
    assert warnings == ["warning: 2 of 3 probes lie outside the solid, where there is nothing to sample "
                        "(NaN in their values): (1.08, 0, 0), (0.5, 0.16, 0)"], out.stderr
    assert "merged" not in out.stderr  # STL shares no corners: merging them is not worth a word
    result = read_result(tmp_path / "r.h5")
    assert any("2 of 3 probes lie outside the solid" in w for w in result.solver.warnings)


def test_a_device_named_as_the_job_or_the_mesh_is_refused_not_read(tmp_path):
    # /dev/zero used to be read until memory ran out (validate, run and voxelize alike)
    (tmp_path / "zero.stl").symlink_to("/dev/zero")
    spec = job(tmp_path, grid={"resolution": 8, "padding": 1})
    data = json.loads(spec.read_text())
    data["geometry"]["mesh"] = "zero.stl"
    spec.write_text(json.dumps(data))
    device = "it is a character device, not a file"
    assert one_error_line(cli("validate", "/dev/zero")) == f"error: cannot read job file '/dev/zero': {device}"
    for args in (("validate", spec), ("run", spec, "-o", tmp_path / "r.h5")):
        line = one_error_line(cli(*args, timeout=60))
        assert line == f"error: geometry.mesh: cannot read '{tmp_path / 'zero.stl'}': {device}", line
    line = one_error_line(cli("voxelize", tmp_path / "zero.stl", "--resolution", "8", "-o", tmp_path / "v.h5", timeout=60))
    assert line == f"error: geometry.mesh: cannot read 'zero.stl': {device}", line
    # a pipe as the mesh waited for a writer forever
    os.mkfifo(tmp_path / "pipe.stl")
    line = one_error_line(cli("voxelize", tmp_path / "pipe.stl", "--resolution", "8", "-o", tmp_path / "v.h5", timeout=60))
    assert line == "error: geometry.mesh: cannot read 'pipe.stl': it is a pipe, not a file", line
    # a pipe is read: a spec handed over on standard input (its mesh named by an absolute path)
    data["geometry"]["mesh"] = str(tmp_path / "cantilever.stl")
    piped = subprocess.run([sys.executable, "-m", "engine.cli", "validate", "/dev/stdin"], input=json.dumps(data),
                           capture_output=True, text=True, timeout=60)
    assert piped.returncode == 0 and piped.stdout.startswith("OK: /dev/stdin"), piped.stderr


def test_a_path_with_a_nul_character_is_an_oserror_in_words():
    from engine.files import read_input

    with pytest.raises(OSError) as info:
        read_input("part\0.stl")
    assert info.value.strerror == "the path holds a NUL character, which no file name can"


def test_cells_far_larger_than_the_part_are_refused_not_rounded_away(tmp_path):
    # a 1 m bar in 1e4 m cells voxelized to "solid 0 (mesh 0.04)" with exit 0, and run raised a
    # ValueError inside the staggered setup (1e308 m cells: an overflow of twice the spacing)
    huge = job(tmp_path, grid={"cell_size": 1e4, "padding": 1})
    reason = ("error: grid.cell_size: 10000 m is over 1000 times the geometry's longest side (1 m); a cell that "
              "large holds all of it and loses it to round-off: give a cell size below the part's size")
    assert one_error_line(cli("validate", huge)) == reason
    assert one_error_line(cli("run", huge, "-o", tmp_path / "r.h5")) == reason
    assert one_error_line(cli("voxelize", STL, "--cell-size", "1e4", "-o", tmp_path / "v.h5")) == reason
    # within that bound a thin rod is still under the fractions' round-off in every cell
    import trimesh

    trimesh.creation.box((1, 1e-3, 1e-3)).export(tmp_path / "rod.stl")
    line = one_error_line(cli("voxelize", tmp_path / "rod.stl", "--cell-size", "1000", "-o", tmp_path / "v.h5"))
    assert line.startswith("error: grid.cell_size: no cell holds a share of the solid above round-off"), line
    assert not list(tmp_path.glob("*.h5"))


# --- what the entry-point sweep left: line ends, a binary STL cut short, polygon messages ---------


def test_a_ply_with_mac_or_doubled_windows_line_ends_validates_as_with_unix_ones(tmp_path):
    # "\r" made the whole file one line to trimesh (exit 2, "not a valid PLY file"); "\r\r\n" (saved
    # twice through a Windows text stream) a blank line after every row; "\r\n" itself was read
    import trimesh

    ply = trimesh.load_mesh(STL).export(file_type="ply", encoding="ascii")
    path = job(tmp_path, geometry={"mesh": "cantilever.ply", "scale": 1.0})
    lines = []
    for mark, end in ((b"", b"\n"), (b"", b"\r"), (b"", b"\r\r\n"), (b"\xef\xbb\xbf", b"\r\n")):
        (tmp_path / "cantilever.ply").write_bytes(mark + ply.replace(b"\n", end))
        out = cli("validate", path)
        assert out.returncode == 0, out.stderr
        lines.append(out.stdout)
    assert lines == [f"OK: {path} (3D, method staggered, analysis static, 12 facets, grid 34x9x9)\n"] * 4


def test_a_binary_stl_cut_at_a_record_boundary_is_exit_2_naming_both_counts(tmp_path):
    # it was read as the records present (a box with a filled hole, an open surface) or, with one or
    # two records left, "no mesh found (is it a valid STL file?)"
    import trimesh

    stl = trimesh.load_mesh(STL).export(file_type="stl")
    path = job(tmp_path)
    for records in (2, 7):
        (tmp_path / "cantilever.stl").write_bytes(stl[:84 + 50 * records])
        size = 84 + 50 * records
        assert one_error_line(cli("validate", path)) == (
            f"error: geometry.mesh: cannot read 'cantilever.stl': the binary STL is cut short: its header gives 12 "
            f"triangles (684 bytes), the file has {size} bytes ({records} whole triangles)")


POLYGON_JOB = {"dimension": 2, "grid": {"resolution": 16, "padding": 1}, "method": {"kind": "staggered"},
               "material": {"youngs_modulus": 1e7, "poisson_ratio": 0.3, "density": 1000},
               "boundaries": [{"kind": "displacement", "region": {"box": [[-0.1, -0.1], [0.05, 1.1]]}, "value": [0, 0]}],
               "loads": {"gravity": [0, -9.81]}, "analysis": {"kind": "static"}}
SQUARE = [[0, 0], [1, 0], [1, 1], [0, 1]]


@pytest.mark.parametrize("loops, reason", [
    ([[[0, 0], [1, 1], [1, 0], [0, 1]]], "polygon 'polygon': loop 0 is not a simple closed curve: it crosses itself "
                                         "at (0.5, 0.5)"),  # was "(Self-intersection[0.5 0.5])", no field
    ([[[0, 0], [2, 0], [2, 2], [1, 2], [1, 1], [1, 2], [0, 2]]], "polygon 'polygon': loop 0 is not a simple closed "
                                                                 "curve: it touches itself at (1, 2)"),
    ([SQUARE, [[0.5, 0.5], [2, 0.5], [2, 2], [0.5, 2]]], "polygon 'polygon': loops 0 and 1 cross each other"),
    ([SQUARE, [[0.5, 0.5]] * 5], "polygon 'polygon': loop 1 encloses no area (1 distinct points)"),
    ([[[0, 0], [1e200, 0], [1e200, 1e200]]], "'polygon' reaches coordinates of 1e+200 m; at most 1e+60 m is supported"),
])
def test_polygon_errors_name_geometry_polygon_and_say_why_in_words(tmp_path, loops, reason):
    path = tmp_path / "job.json"
    path.write_text(json.dumps({**POLYGON_JOB, "geometry": {"polygon": loops}}))
    assert one_error_line(cli("validate", path)) == f"error: geometry.polygon: {reason}"


def test_a_polygon_error_is_the_same_line_in_run(tmp_path):
    path = tmp_path / "job.json"
    path.write_text(json.dumps({**POLYGON_JOB, "geometry": {"polygon": [[[0, 0], [1, 1], [1, 0], [0, 1]]]}}))
    assert one_error_line(cli("run", path, "-o", tmp_path / "r.h5")) == (
        "error: geometry.polygon: polygon 'polygon': loop 0 is not a simple closed curve: it crosses itself at (0.5, 0.5)")
    assert not list(tmp_path.glob("*.h5"))
