"""A bounded fuzz of POST /jobs on a real server on loopback: hundreds of malformed specs, meshes
and multipart bodies from a fixed seed, each answered 4xx with a message in words, never 5xx.

The cases are generated, not listed, but deterministically (``random.Random(SEED)``): a failure
names its case number and reproduces on the next run.
"""

from __future__ import annotations

import bz2
import copy
import gzip
import io
import json
import lzma
import random
import struct
import time
import zipfile

import httpx
import pytest
from service_helpers import MESH, Server, cantilever, shared_cache_dir
from test_service_hardening import RAW

SEED = 18
CASES = 400
TIME_BUDGET = 60.0  # seconds for all cases together

NASTY = [None, True, -1, 0, 2**63, -(2**63) - 1, 10**40, 1e308, -1e308, 1e-320, float("nan"), float("inf"),
         "", "x" * 5000, "\u202e\ud800", [], {}, [[[]]], {"": None}, [1] * 1000, "1e3", [None, "a", {}]]
SUFFIXES = [".stl", ".obj", ".ply", ".off", ".glb", ".gltf", ".3mf", ".zip", ".bz2", ".gz", ".xz", ".tar.gz",
            ".stl.bz2", ".stl.gz", ".svg", ".dxf", ".foo", ""]


def _leaves(value, path=()):
    """Every path into a JSON document (objects and arrays), leaves and inner nodes alike."""
    yield path
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _leaves(v, (*path, k))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _leaves(v, (*path, i))


def _set(doc, path, value):
    for key in path[:-1]:
        doc = doc[key]
    doc[path[-1]] = value


def _delete(doc, path):
    for key in path[:-1]:
        doc = doc[key]
    del doc[path[-1]]


def mutated_spec(rng: random.Random) -> str:
    """The example spec with one to three fields replaced by nasty values, removed or added."""
    spec = cantilever(16)
    for _ in range(rng.randint(1, 3)):
        paths = [p for p in _leaves(spec) if p]
        path = rng.choice(paths)
        action = rng.random()
        if action < 0.6:
            _set(spec, path, copy.deepcopy(rng.choice(NASTY)))
        elif action < 0.8:
            _delete(spec, path)
        else:
            parent = path[:-1]
            target = spec
            for key in parent:
                target = target[key]
            if isinstance(target, dict):
                target[f"unknown_{rng.randint(0, 99)}"] = rng.choice(NASTY)
            else:
                _delete(spec, path)
    return json.dumps(spec)  # NaN and Infinity as JavaScript writes them: not JSON


def raw_spec(rng: random.Random) -> bytes:
    """Spec text that is not a JSON object, or is one broken at the byte level."""
    text = json.dumps(cantilever(16)).encode()
    kind = rng.randrange(9)
    if kind == 0:
        return text[: rng.randrange(1, len(text))]  # truncated
    if kind == 1:
        data = bytearray(text)
        for _ in range(rng.randint(1, 8)):
            data[rng.randrange(len(data))] = rng.randrange(256)
        return bytes(data)
    if kind == 2:
        depth = rng.choice([900, 1000, 5000, 50000])
        return rng.choice([b"[", b'{"a":']) * depth
    if kind == 3:
        return b'{"dimension": ' + b"7" * rng.choice([4301, 5000, 100000]) + b"}"
    if kind == 4:
        return rng.choice([b"null", b"[]", b'"spec"', b"3", b"true", b" ", b"\xef\xbb\xbf{}", b"{}" * 3])
    if kind == 5:
        return b"\xff\xfe" + text.decode().encode("utf-16-le")  # not UTF-8
    if kind == 6:
        return text.replace(b'"grid"', b'"grid": 1, "grid"')  # a repeated key
    if kind == 7:
        return bytes(rng.randrange(256) for _ in range(rng.randint(1, 400)))
    return b'{"a": "' + b"\\ud800" * 50 + b'"}'


def bad_mesh(rng: random.Random) -> tuple[str, bytes]:
    """A malformed mesh under a random (or fitting) name."""
    kind = rng.randrange(10)
    suffix = rng.choice(SUFFIXES)
    if kind == 0:
        return f"m{suffix}", bytes(rng.randrange(256) for _ in range(rng.randint(1, 2000)))
    if kind == 1:
        return "m.stl", MESH[: rng.randrange(1, len(MESH))]
    if kind == 2:  # binary STL whose count promises far more facets than follow
        count = rng.choice([1, 10**6, 2**32 - 1])
        return "m.stl", b"\0" * 80 + struct.pack("<I", count) + bytes(rng.randrange(256) for _ in range(100))
    if kind == 3:
        head = rng.choice([b"element vertex 1000000000\nproperty float x\n", b"element vertex 3\nproperty float y\n",
                           b"element face 5\nproperty list uchar int vertex_indices\n"])
        return "m.ply", b"ply\nformat ascii 1.0\n" + head + b"end_header\n1 2 3\n"
    if kind == 4:
        return "m.obj", rng.choice([b"v 0 0 0\nf 1 2 99999\n", b"v nan nan nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
                                    b"f 1 2 3\n", b"v 1e400 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\n"])
    if kind == 5:
        body = json.dumps(rng.choice([{"asset": {}}, {"meshes": [{"primitives": [{"attributes": {"POSITION": 7}}]}]},
                                      {"buffers": [{"uri": "../../etc/passwd", "byteLength": 10}]}, []]))
        return rng.choice(["m.gltf", "m.glb"]), body.encode()
    if kind == 6:  # a glTF binary whose header declares huge chunks
        return "m.glb", b"glTF" + struct.pack("<II", 2, 2**31) + struct.pack("<I", 2**31) + b"JSON" + b"{}"
    if kind == 7:
        packer = rng.choice([(".bz2", bz2.compress), (".gz", gzip.compress), (".xz", lzma.compress)])
        return f"m.stl{packer[0]}", packer[1](bytes(rng.randrange(256) for _ in range(500)))
    if kind == 8:
        out = io.BytesIO()
        with zipfile.ZipFile(out, "w") as archive:
            archive.writestr(rng.choice(["m.stl", "3D/3dmodel.model", "a/../../m.obj", "m.zip"]), MESH[:100])
        return rng.choice(["m.zip", "m.3mf"]), out.getvalue()
    return "m.stl", b"solid x\n facet normal 0 0 1\n outer loop\n vertex 1 2\n endloop\n endfacet\nendsolid\n"


def bad_request(rng: random.Random, case: int) -> dict:
    """httpx.request keyword arguments of one malformed POST /jobs."""
    kind = case % 4
    if kind == 0:
        return {"data": {"spec": mutated_spec(rng)}, "files": {"mesh": ("cantilever.stl", MESH)}}
    if kind == 1:
        return {"files": {"spec": ("job.json", raw_spec(rng)), "mesh": ("cantilever.stl", MESH)}}
    if kind == 2:
        name, data = bad_mesh(rng)
        return {"data": {"spec": json.dumps(cantilever(16))}, "files": {"mesh": (name, data)}}
    boundary = "fz" + str(rng.randrange(10**6))
    bodies = [
        {"content": b"--" + boundary.encode() + b"\r\nContent-Disposition: form-data\r\n\r\nx\r\n--" + boundary.encode(),
         "headers": {"Content-Type": f"multipart/form-data; boundary={boundary}"}},
        {"content": json.dumps(cantilever(16)).encode(), "headers": {"Content-Type": "application/json"}},
        {"content": b"spec=%7B%7D", "headers": {"Content-Type": "application/x-www-form-urlencoded"}},
        {"files": {"mesh": ("c.stl", MESH)}},
        {"data": {"spec": json.dumps(cantilever(16)), "mesh": "not a file"}},
        {"content": bytes(rng.randrange(256) for _ in range(300)),
         "headers": {"Content-Type": "multipart/form-data; boundary=" + boundary}},
        {"files": [("spec", ("a.json", b"{}")), ("spec", ("b.json", b"[]")), ("mesh", ("c.stl", MESH))]},
        {"data": {"spec": json.dumps(cantilever(16))}, "files": {"mesh": ("c.stl", b"")}},
    ]
    return rng.choice(bodies)


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    srv = Server(tmp_path_factory.mktemp("fuzz") / "data", shared_cache_dir(tmp_path_factory), workers=1,
                 max_cells=100_000, max_upload_bytes=2_000_000)
    srv.start()
    yield srv
    srv.close()


def test_fuzzed_submissions_never_get_a_5xx(server):
    rng = random.Random(SEED)
    c = httpx.Client(base_url=server.url, timeout=30)
    statuses, accepted, failures = {}, [], []
    started = time.monotonic()
    for case in range(CASES):
        request = bad_request(rng, case)
        try:
            r = c.post("/jobs", **request)
        except httpx.HTTPError as exc:  # a dropped connection is as bad as a 500
            failures.append((case, "connection", repr(exc)))
            c = httpx.Client(base_url=server.url, timeout=30)
            continue
        statuses[r.status_code] = statuses.get(r.status_code, 0) + 1
        if r.status_code == 202:  # a mutation that left a valid spec: fine, but not left running
            accepted.append(r.json()["id"])
            continue
        if not 400 <= r.status_code < 500:
            failures.append((case, r.status_code, r.text[:300]))
            continue
        detail = r.json()["detail"]
        messages = [detail] if isinstance(detail, str) else [e["msg"] for e in detail]
        if not all(messages) or any(RAW.search(m) for m in messages):
            failures.append((case, r.status_code, messages))
    elapsed = time.monotonic() - started
    for job_id in accepted:
        c.delete(f"/jobs/{job_id}")
    print(f"{CASES} fuzzed submissions in {elapsed:.1f} s: {dict(sorted(statuses.items()))}")
    assert not failures, failures[:10]
    assert sum(n for s, n in statuses.items() if 400 <= s < 500) >= 200
    assert elapsed < TIME_BUDGET
    assert c.get("/health").json()["status"] == "ok"
