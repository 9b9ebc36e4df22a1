"""Peak resident memory of a benchmark's job process."""

from __future__ import annotations

import resource
from pathlib import Path


def peak_rss_bytes() -> int:
    """This process's peak resident memory [bytes]: VmHWM of /proc/self/status, the high-water mark of
    its own address space. ``ru_maxrss`` also keeps that of the address space it was forked from, so a
    job started by a large process (a test run) reads as large as its parent."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) * 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # not Linux: the kernel's figure
