"""Files of a job under the data directory: the uploaded mesh, staging areas and the result.

Layout (``<id>`` is a server-made token; nothing a request sends becomes part of a path)::

    <data_dir>/jobs/<id>/mesh<suffix>          the upload (suffix from an allow-list of formats)
    <data_dir>/jobs/<id>/staging-<attempt>/    where an attempt writes its result
    <data_dir>/jobs/<id>/result/<id>.h5        the published result (+ <id>.xdmf beside it)

An attempt writes ``<id>.h5`` + ``<id>.xdmf`` inside its staging directory and the directory is
renamed to ``result`` in one step, so the pair appears complete or not at all; the job is
marked succeeded only after that rename.
"""

from __future__ import annotations

import os
import re
import secrets
import shutil
from pathlib import Path

JOB_ID_PATTERN = r"^[A-Za-z0-9_-]{22}$"
_JOB_ID = re.compile(JOB_ID_PATTERN)
_SUFFIX = re.compile(r"^\.[a-z0-9]{1,8}$")


def new_job_id() -> str:
    """An unguessable job id: 128 random bits, URL-safe base64 (22 characters)."""
    return secrets.token_urlsafe(16)


def mesh_suffix(filename: str | None) -> str:
    """The lower-case suffix of an uploaded file's name ('' when it has none or an odd one).

    Only the suffix survives: the engine reads the format from it; the name itself is discarded.
    """
    suffix = Path(filename or "").suffix.lower()
    return suffix if _SUFFIX.match(suffix) else ""


def display_name(filename: str | None, suffix: str) -> str:
    """The upload's name for messages only: safe characters, at most 64, ending in ``suffix``."""
    stem = re.sub(r"[^A-Za-z0-9._-]", "_", Path(filename or "").stem)[:56].lstrip(".") or "mesh"
    return f"{stem}{suffix}"


class Storage:
    """Paths and file operations of jobs below ``root`` (``<data_dir>/jobs``)."""

    def __init__(self, data_dir: str | os.PathLike):
        self.root = Path(data_dir) / "jobs"
        self.root.mkdir(parents=True, exist_ok=True)

    def job_dir(self, job_id: str) -> Path:
        # the id comes from our own table, but check anyway: a path must never be built from junk
        if not _JOB_ID.match(job_id):
            raise ValueError(f"not a job id: {job_id!r}")
        return self.root / job_id

    def mesh_path(self, job_id: str, suffix: str) -> Path:
        return self.job_dir(job_id) / f"mesh{suffix}"

    def save_mesh(self, job_id: str, suffix: str, data: bytes) -> Path:
        """Store the upload durably (fsync) before the job is queued."""
        path = self.mesh_path(job_id, suffix)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.tmp")
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
        return path

    def staging_dir(self, job_id: str, attempt: int) -> Path:
        return self.job_dir(job_id) / f"staging-{attempt}"

    def result_dir(self, job_id: str) -> Path:
        return self.job_dir(job_id) / "result"

    def result_path(self, job_id: str) -> Path:
        return self.result_dir(job_id) / f"{job_id}.h5"

    def xdmf_path(self, job_id: str) -> Path:
        return self.result_dir(job_id) / f"{job_id}.xdmf"

    def result_file(self, job_id: str, suffix: str) -> Path:
        """A file published beside the HDF5 result: ``<id><suffix>`` (".vtkhdf", ".solid.xdmf",
        ".surface.xdmf", ".png" for the preview picture)."""
        return self.result_dir(job_id) / f"{job_id}{suffix}"

    def clear_attempts(self, job_id: str) -> None:
        """Remove staging areas and any unpublished result of earlier attempts."""
        d = self.job_dir(job_id)
        if not d.is_dir():
            return
        for child in d.iterdir():
            if child.name.startswith("staging-") or child.name == "result":
                shutil.rmtree(child, ignore_errors=True)

    def publish(self, job_id: str, attempt: int) -> int:
        """Rename the attempt's staging directory to ``result``; returns the HDF5 size in bytes."""
        staging = self.staging_dir(job_id, attempt)
        final = self.result_dir(job_id)
        if not (staging / f"{job_id}.h5").is_file():
            raise FileNotFoundError(f"attempt {attempt} of job {job_id} left no result file")
        if final.exists():  # left by an attempt that died between its rename and its status update
            shutil.rmtree(final)
        os.rename(staging, final)
        _fsync_dir(final.parent)
        return self.result_path(job_id).stat().st_size

    def delete(self, job_id: str) -> None:
        """Remove every file of a job."""
        shutil.rmtree(self.job_dir(job_id), ignore_errors=True)


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
