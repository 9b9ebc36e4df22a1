"""The service's command of the ``voxelastic`` CLI: ``voxelastic serve``.

The engine's CLI knows no service: it adds the subcommands that installed packages register under
the entry-point group ``voxelastic.commands`` (pyproject.toml), each a function taking the CLI's
subparsers.
"""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``serve`` to the CLI's subparsers ``sub``."""
    p = sub.add_parser("serve", help="run the job service (REST API + workers); settings from VOXELASTIC_* variables")
    p.add_argument("--host", help="bind address (default VOXELASTIC_HOST or 127.0.0.1)")
    p.add_argument("--port", type=int, help="port (default VOXELASTIC_PORT or 8000)")
    p.add_argument("--log-level", default="info", choices=("critical", "error", "warning", "info", "debug"))
    p.set_defaults(func=_serve)


def _serve(args: argparse.Namespace) -> int:
    from .server import serve

    return serve(args.host, args.port, args.log_level)
