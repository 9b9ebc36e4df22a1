"""Compressed and archived mesh files, inflated as a stream under a cap on the inflated size.

A few hundred bytes of bzip2 can hold a gigabyte of zeros, so the size of an upload says nothing
about the memory its contents need. Everything here reads through the decompressor in bounded
steps (``read(n)`` on the stream, never ``read()``), counts what came out and stops with a
:class:`InflateLimitError` as soon as the total would pass ``limit``. Sizes an archive declares
are never trusted: ZIP and tar headers can lie, so only the bytes actually produced count.

Containers: ``.gz``, ``.bz2``, ``.xz`` (one file: the inner name is the outer one without the
suffix), ``.zip`` and ``.tar`` (also ``.tar.gz``/``.tgz``, ``.tar.bz2``/``.tbz2``,
``.tar.xz``/``.txz``). Archives nested in archives are not opened.
"""

from __future__ import annotations

import bz2
import gzip
import io
import lzma
import tarfile
import zipfile
from pathlib import PurePosixPath

from engine.errors import GeometryError

# Default cap on what one mesh file may inflate to [bytes]: the CLI and the workers use it; the
# service passes its own (VOXELASTIC_MAX_INFLATED_BYTES).
DEFAULT_MAX_INFLATED = 2**30
# Archives with more members than this are refused before reading them: each costs a header
# parse and a dictionary entry even when empty.
MAX_MEMBERS = 1000
_CHUNK = 1 << 20

# suffix -> (kind, stream opener); longest suffixes are matched first
_TAR_STREAMS = {".tar": "tar", ".tar.gz": "tar", ".tgz": "tar", ".tar.bz2": "tar", ".tbz2": "tar", ".tar.xz": "tar",
                ".txz": "tar"}
_SINGLE = {
    ".gz": lambda f: gzip.GzipFile(fileobj=f, mode="rb"),
    ".bz2": lambda f: bz2.BZ2File(f, mode="rb"),
    ".xz": lambda f: lzma.LZMAFile(f, mode="rb"),
}
_SUFFIXES = sorted([*_TAR_STREAMS, *_SINGLE, ".zip"], key=len, reverse=True)


class InflateLimitError(GeometryError):
    """The contents of a compressed or archived file exceed the cap on the inflated size."""

    def __init__(self, name: str, limit: int):
        super().__init__(
            f"'{name}' inflates to more than {limit} bytes, the limit for the contents of compressed "
            "or archived meshes; upload the mesh uncompressed or make it smaller"
        )
        self.limit = limit


class ExtendedHeaderTooLarge(InflateLimitError):
    """A tar extended header (pax, GNU long name or link) larger than names and attributes need."""

    def __init__(self, name: str, size: int, cap: int):
        GeometryError.__init__(
            self, f"'{name}' holds a tar extended header (pax or GNU long name) of {size} bytes, over the "
                  f"{cap} bytes a tar may use for a file's name and attributes; this is not a mesh archive"
        )
        self.limit = cap


def container_suffix(name: str) -> str | None:
    """The compression/archive suffix of ``name`` ('.tar.gz', '.zip', ...), or None for a plain file."""
    lower = name.lower()
    return next((s for s in _SUFFIXES if lower.endswith(s)), None)


def inflate(name: str, data: bytes, limit: int = DEFAULT_MAX_INFLATED) -> dict[str, bytes]:
    """The files inside ``data`` (named ``name``), as {member name: bytes}, at most ``limit`` bytes in all.

    Raises :class:`InflateLimitError` beyond the cap and ``GeometryError`` for a damaged file.
    """
    suffix = container_suffix(name)
    if suffix is None:
        raise GeometryError(f"'{name}' is not a compressed or archived file")
    try:
        if suffix == ".zip":
            return _unzip(name, data, limit)
        if suffix in _TAR_STREAMS:
            return _untar(name, data, limit)
        inner = PurePosixPath(name).name[: -len(suffix)] or "mesh"
        with _SINGLE[suffix](io.BytesIO(data)) as stream:
            return {inner: _read_capped(stream, limit, name)}
    except InflateLimitError:
        raise
    except (OSError, EOFError, ValueError, zipfile.BadZipFile, tarfile.TarError, lzma.LZMAError, RuntimeError,
            NotImplementedError):
        # damaged or truncated streams, unsupported ZIP methods or encryption: a bad file to the user
        kind = {".zip": "ZIP archive", ".gz": "gzip file", ".bz2": "bzip2 file", ".xz": "xz file"}.get(suffix, "tar archive")
        raise GeometryError(f"cannot read '{name}': it is not a valid {kind} (damaged, truncated or encrypted)") from None


def check_zip_container(name: str, data: bytes, limit: int) -> None:
    """Raise unless every member of a ZIP-based format (3MF) inflates within ``limit`` in all.

    Such formats are read by their own loaders, which inflate whole members; checking first
    bounds what they can be made to allocate.
    """
    total = 0
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as archive:
            infos = archive.infolist()
            if len(infos) > MAX_MEMBERS:
                raise GeometryError(f"cannot read '{name}': {len(infos)} files inside, more than {MAX_MEMBERS}")
            for info in infos:
                with archive.open(info) as stream:
                    while chunk := stream.read(min(_CHUNK, limit - total + 1)):
                        total += len(chunk)
                        if total > limit:
                            raise InflateLimitError(name, limit)
    except (OSError, EOFError, ValueError, zipfile.BadZipFile, RuntimeError, NotImplementedError):
        return  # not a readable ZIP: the format's own loader says what is wrong with it


def _read_capped(stream, limit: int, name: str, used: int = 0) -> bytes:
    """Read ``stream`` to its end in chunks; InflateLimitError once ``used`` + its length passes ``limit``."""
    parts, total = [], used
    while chunk := stream.read(min(_CHUNK, limit - total + 1)):
        total += len(chunk)
        if total > limit:
            raise InflateLimitError(name, limit)
        parts.append(chunk)
    return b"".join(parts)


def _unzip(name: str, data: bytes, limit: int) -> dict[str, bytes]:
    out: dict[str, bytes] = {}
    used = 0
    with zipfile.ZipFile(io.BytesIO(data)) as archive:
        infos = [i for i in archive.infolist() if not i.is_dir()]
        if len(infos) > MAX_MEMBERS:
            raise GeometryError(f"cannot read '{name}': {len(infos)} files inside, more than {MAX_MEMBERS}")
        for info in infos:
            if info.filename in out:  # which of the two was meant cannot be told: refuse, naming it
                raise GeometryError(f"cannot read '{name}': it holds two files named '{info.filename[:200]}'; "
                                    "an archive must name each file once")
            with archive.open(info) as stream:
                member = _read_capped(stream, limit, name, used)
            used += len(member)
            out[info.filename] = member
    return out


class _CappedStream:
    """A read-only stream that raises InflateLimitError once more than ``cap`` bytes came out of it.

    tarfile reads a pax or GNU long-name extended header whole, before any member, with sizes the
    header declares: counting member contents alone let a 2.3 MB upload inflate 500 MiB there."""

    def __init__(self, raw, cap: int, name: str, limit: int):
        self.raw, self.cap, self.name, self.limit, self.count = raw, cap, name, limit, 0

    def read(self, size: int = -1) -> bytes:
        room = self.cap - self.count + 1
        chunk = self.raw.read(room if size is None or size < 0 else min(size, room))
        self.count += len(chunk)
        if self.count > self.cap:
            raise InflateLimitError(self.name, self.limit)
        return chunk


# Extended headers hold a name (at most PATH_MAX, 4 kB) and a few attributes; tarfile reads one whole
# and then copies it while decoding, so its size is capped on its own, before it is read
MAX_EXTENDED_HEADER = 1 << 20
_EXTENDED = (tarfile.XHDTYPE, tarfile.XGLTYPE, tarfile.SOLARIS_XHDTYPE, tarfile.GNUTYPE_LONGNAME,
             tarfile.GNUTYPE_LONGLINK)


class _BoundedTarInfo(tarfile.TarInfo):
    _archive_name = "archive"

    def _proc_member(self, tarfile_):
        if self.type in _EXTENDED and self.size > MAX_EXTENDED_HEADER:
            raise ExtendedHeaderTooLarge(self._archive_name, self.size, MAX_EXTENDED_HEADER)
        return super()._proc_member(tarfile_)


# the tar format's own bytes beside the members' contents, allowed on top of the cap: per member a
# 512-byte header, a pax header with its own (small) record and padding; per archive the
# end-of-archive blocks padded to a 10 kB record, and tarfile's read-ahead of one record
_TAR_PER_MEMBER = 2048
_TAR_SLACK = 32 * 1024
# compressed tar streams by their magic bytes (what tarfile's 'r|*' looks at)
_TAR_COMPRESSION = ((b"\x1f\x8b", _SINGLE[".gz"]), (b"BZh", _SINGLE[".bz2"]), (b"\xfd7zXZ\x00", _SINGLE[".xz"]))


def _untar(name: str, data: bytes, limit: int) -> dict[str, bytes]:
    out: dict[str, bytes] = {}
    used = declared = count = 0
    opener = next((open_ for magic, open_ in _TAR_COMPRESSION if data.startswith(magic)), None)
    raw = opener(io.BytesIO(data)) if opener else io.BytesIO(data)
    # every byte the decompressor produces counts (headers, extended headers, padding), not only
    # what members declare or hold
    stream = _CappedStream(raw, limit + _TAR_SLACK + _TAR_PER_MEMBER, name, limit)
    # stream mode ('r|'): one pass, no seeking back; skipping a member still inflates it, so the
    # sizes the headers declare are capped too, which bounds the work as well as the memory
    tarinfo = type("_TarInfo", (_BoundedTarInfo,), {"_archive_name": name})
    with raw, tarfile.open(fileobj=stream, mode="r|", tarinfo=tarinfo) as archive:
        for member in archive:
            count += 1
            if count > MAX_MEMBERS:
                raise GeometryError(f"cannot read '{name}': more than {MAX_MEMBERS} files inside")
            stream.cap = limit + _TAR_SLACK + _TAR_PER_MEMBER * (count + 1)  # up to the next member's header
            declared += max(member.size, 0)
            if declared > limit:
                raise InflateLimitError(name, limit)
            if not member.isfile():
                continue
            content_stream = archive.extractfile(member)
            if content_stream is None:
                continue
            content = _read_capped(content_stream, limit, name, used)
            used += len(content)
            if member.name in out:  # which of the two was meant cannot be told: refuse, naming it
                raise GeometryError(f"cannot read '{name}': it holds two files named '{member.name[:200]}'; "
                                    "an archive must name each file once")
            out[member.name] = content
    return out
