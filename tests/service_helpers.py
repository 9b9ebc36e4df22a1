"""Helpers of the service tests: a real ``voxelastic serve`` on a loopback port, jobs, waiting.

Nothing here is a mock: servers are subprocesses started exactly as a user would, with settings
through ``VOXELASTIC_*`` variables; Redis and PostgreSQL for the Celery test are real servers
(URLs from ``.ci/run``, or private instances started here when the binaries exist).
"""

from __future__ import annotations

import copy
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
import psutil

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "cantilever.json"
MESH = (ROOT / "examples" / "cantilever.stl").read_bytes()
TERMINAL = {"succeeded", "failed", "cancelled"}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def cantilever(resolution: int = 16, analysis: dict | None = None, **solver) -> dict:
    """The bundled example at another resolution (16: a job of a fraction of a second, warm)."""
    spec = json.loads(EXAMPLE.read_text())
    spec["grid"] = {"resolution": resolution, "padding": 1}
    if analysis is not None:
        spec["analysis"] = analysis
    spec["solver"].update(solver)
    return spec


def long_job(steps: int = 400) -> dict:
    """A job that runs for minutes (64^3-ish dynamic, ~0.5 s per step): to cancel, kill, time out. Solved
    by the V-cycle: "auto" would factorise this grid once, and each step would then take milliseconds."""
    spec = cantilever(64, {"kind": "dynamic", "time_step": 1e-3, "steps": steps})
    spec["method"] = {"kind": "staggered", "solver": "iterative"}
    return spec


_warmed: set[str] = set()


def shared_cache_dir(tmp_factory) -> str:
    """Taichi's offline kernel cache shared by every test server, filled once per session.

    Taichi writes its offline cache when a process exits normally; worker processes stopped by a
    limit or a cancellation never do. One CLI run of the small job fills it up front, so that a
    fresh worker process loads the common kernels instead of compiling them inside a test's
    wall-time limit.
    """
    path = os.environ.get("VOXELASTIC_CACHE_DIR") or str(tmp_factory.getbasetemp() / "voxelastic-cache")
    if path not in _warmed:
        work = Path(tmp_factory.mktemp("warm-cache"))
        (work / "job.json").write_text(json.dumps(cantilever(16)))
        (work / "cantilever.stl").write_bytes(MESH)
        out = subprocess.run([sys.executable, "-m", "engine.cli", "run", str(work / "job.json"), "-o", str(work / "r.h5")],
                             capture_output=True, text=True, timeout=300, env={**os.environ, "VOXELASTIC_CACHE_DIR": path})
        assert out.returncode == 0, out.stderr
        _warmed.add(path)
    return path


class Server:
    """``python -m engine.cli serve`` in a subprocess, with an httpx client bound to it."""

    def __init__(self, data_dir: Path, cache_dir: str, *, token: str | None = None, **settings):
        self.data_dir, self.cache_dir, self.token = Path(data_dir), cache_dir, token
        self.settings = {k: str(v) for k, v in settings.items()}
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.proc: subprocess.Popen | None = None
        self.log_path = self.data_dir.parent / f"{self.data_dir.name}-server-{self.port}.log"
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        self.client = httpx.Client(base_url=self.url, headers=headers, timeout=60)

    def env(self) -> dict[str, str]:
        env = dict(os.environ)
        env.update({"VOXELASTIC_DATA_DIR": str(self.data_dir), "VOXELASTIC_CACHE_DIR": self.cache_dir,
                    "PYTHONUNBUFFERED": "1"})
        env.update({f"VOXELASTIC_{k.upper()}": v for k, v in self.settings.items()})
        if self.token:
            env["VOXELASTIC_TOKENS"] = self.token
        return env

    def start(self, timeout: float = 120) -> Server:
        log = open(self.log_path, "ab")
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "engine.cli", "serve", "--host", "127.0.0.1", "--port", str(self.port),
             "--log-level", "warning"],
            cwd=ROOT, env=self.env(), stdout=log, stderr=subprocess.STDOUT,
        )
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"server exited with {self.proc.returncode}:\n{self.log()}")
            try:
                r = httpx.get(self.url + "/health", timeout=2)
                queue = r.json()["queue"] if r.status_code == 200 else {}
                # local pool: every worker process up (Taichi initialised); Celery: the broker answers
                if r.status_code == 200 and queue.get("processes_alive", 0) == queue.get("workers", 0):
                    return self
            except httpx.HTTPError:
                pass
            time.sleep(0.2)
        raise RuntimeError(f"server did not become healthy in {timeout} s:\n{self.log()}")

    def log(self) -> str:
        return self.log_path.read_text(errors="replace") if self.log_path.exists() else ""

    def children(self) -> list[psutil.Process]:
        try:
            return psutil.Process(self.proc.pid).children(recursive=True)
        except psutil.Error:
            return []

    def stop(self, sig: int = signal.SIGTERM, timeout: float = 60) -> int:
        if self.proc is None or self.proc.poll() is not None:
            return self.proc.returncode if self.proc else 0
        self.proc.send_signal(sig)
        try:
            return self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            return self.proc.wait(10)

    def close(self) -> None:
        kids = self.children()
        self.stop()
        for p in kids:  # nothing may outlive the server, but never leak into other tests
            try:
                p.kill()
            except psutil.Error:
                pass
        self.client.close()

    # --- jobs -----------------------------------------------------------------------------------

    def submit(self, spec: dict | str, mesh: bytes | None = MESH, *, filename: str = "cantilever.stl",
               headers: dict | None = None) -> httpx.Response:
        files = {"mesh": (filename, mesh, "application/octet-stream")} if mesh is not None else None
        data = {"spec": spec if isinstance(spec, str) else json.dumps(spec)}
        return self.client.post("/jobs", data=data, files=files, headers=headers or {})

    def submit_ok(self, spec: dict, **kw) -> str:
        r = self.submit(spec, **kw)
        assert r.status_code == 202, r.text
        return r.json()["id"]

    def job(self, job_id: str) -> dict:
        r = self.client.get(f"/jobs/{job_id}")
        assert r.status_code == 200, r.text
        return r.json()

    def wait(self, job_id: str, until=lambda j: j["status"] in TERMINAL, timeout: float = 120) -> dict:
        deadline = time.monotonic() + timeout
        while True:
            job = self.job(job_id)
            if until(job):
                return job
            if time.monotonic() > deadline:
                raise AssertionError(f"job {job_id} did not reach the condition in {timeout} s: {job}\n{self.log()[-3000:]}")
            time.sleep(0.05)

    def wait_running(self, job_id: str, stage: str | None = "solve", timeout: float = 120) -> dict:
        """Until the job runs on a known worker process (and has reached ``stage``, if given)."""
        def running(j: dict) -> bool:
            return j["status"] == "running" and bool(j["worker"]) and stage in (None, j["progress"]["stage"])

        job = self.wait(job_id, lambda j: j["status"] in TERMINAL or running(j), timeout)
        assert running(job), job
        return job


def worker_pid(job: dict) -> int:
    return int(job["worker"].rsplit(":", 1)[1])


def gone(pid: int, timeout: float = 10) -> bool:
    """True once ``pid`` no longer runs (reaped, or a zombie waiting for its dead parent)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            if psutil.Process(pid).status() == psutil.STATUS_ZOMBIE:
                return True
        except psutil.NoSuchProcess:
            return True
        time.sleep(0.05)
    return False


def with_spec(spec: dict, **changes) -> dict:
    out = copy.deepcopy(spec)
    out.update(changes)
    return out


# --- Redis and PostgreSQL for the Celery test -----------------------------------------------------


class Backing:
    """A Redis URL and a PostgreSQL URL; private servers are stopped by :meth:`close`."""

    def __init__(self, broker_url: str, database_url: str, procs: list | None = None, cleanups: list | None = None):
        self.broker_url, self.database_url = broker_url, database_url
        self._procs, self._cleanups = procs or [], cleanups or []

    def close(self) -> None:
        for p in self._procs:
            p.terminate()
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()
        for fn in self._cleanups:
            fn()


def _wait_port(port: int, timeout: float = 30) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.5):
                return True
        except OSError:
            time.sleep(0.1)
    return False


def start_backing(tmp: Path) -> Backing | str:
    """URLs from VOXELASTIC_TEST_BROKER_URL / VOXELASTIC_TEST_DATABASE_URL (set by .ci/run), else
    private redis-server and PostgreSQL instances; a string says why neither is possible."""
    broker = os.environ.get("VOXELASTIC_TEST_BROKER_URL")
    database = os.environ.get("VOXELASTIC_TEST_DATABASE_URL")
    procs, cleanups = [], []
    if not broker:
        redis = shutil.which("redis-server")
        if redis is None:
            return "no VOXELASTIC_TEST_BROKER_URL and no redis-server binary (.ci/run installs and starts it)"
        port = free_port()
        procs.append(subprocess.Popen([redis, "--port", str(port), "--bind", "127.0.0.1", "--save", "",
                                       "--appendonly", "no", "--dir", str(tmp)], stdout=subprocess.DEVNULL))
        if not _wait_port(port):
            return "redis-server did not start"
        broker = f"redis://127.0.0.1:{port}/0"
    if not database:
        found = _private_postgres(tmp, procs, cleanups)
        if isinstance(found, str) and not found.startswith("postgresql"):
            Backing(broker, "", procs, cleanups).close()
            return found
        database = found
    return Backing(broker, database, procs, cleanups)


def _pg_bin(name: str) -> str | None:
    found = shutil.which(name)
    if found:
        return found
    for d in sorted(Path("/usr/lib/postgresql").glob("*/bin"), reverse=True):
        if (d / name).exists():
            return str(d / name)
    return None


def _private_postgres(tmp: Path, procs: list, cleanups: list) -> str:
    initdb, pg_ctl = _pg_bin("initdb"), _pg_bin("pg_ctl")
    if not initdb or not pg_ctl:
        return "no VOXELASTIC_TEST_DATABASE_URL and no PostgreSQL binaries (.ci/run installs and starts it)"
    # not below pytest's temporary directory: that one is private to us, and as root the server
    # must run as another user (PostgreSQL refuses root)
    import tempfile

    data = Path(tempfile.mkdtemp(prefix="voxelastic-test-pg-"))
    cleanups.append(lambda: shutil.rmtree(data, ignore_errors=True))
    run_as: list[str] = []
    if os.geteuid() == 0:
        try:
            import pwd

            pw = pwd.getpwnam("postgres")
        except KeyError:
            return "running as root without a 'postgres' user to run a private PostgreSQL"
        os.chown(data, pw.pw_uid, pw.pw_gid)
        run_as = ["runuser", "-u", "postgres", "--"]
    port = free_port()
    out = subprocess.run([*run_as, initdb, "-D", str(data), "-U", "voxelastic", "--auth=trust", "-E", "UTF8"],
                         capture_output=True, text=True)
    if out.returncode != 0:
        return f"initdb failed: {out.stderr[-500:]}"
    start = subprocess.run([*run_as, pg_ctl, "-D", str(data), "-w", "-l", str(data / "log"), "-o",
                            f"-p {port} -k {data} -c listen_addresses=127.0.0.1 -c fsync=off", "start"],
                           capture_output=True, text=True)
    if start.returncode != 0:
        return f"pg_ctl start failed: {start.stderr[-500:]}"
    cleanups.insert(0, lambda: subprocess.run([*run_as, pg_ctl, "-D", str(data), "-m", "immediate", "stop"],
                                              capture_output=True))
    return f"postgresql+psycopg://voxelastic@127.0.0.1:{port}/postgres"
