"""Write the job spec's JSON Schema to ``schemas/json/job.schema.json``.

    python -m schemas.export            # (re)write the file
    python -m schemas.export --check    # exit 1 if the committed file differs from the models
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from .job import job_json_schema

SCHEMA_PATH = Path(__file__).resolve().parent / "json" / "job.schema.json"


def schema_text() -> str:
    """The schema file's exact contents: sorted keys, indent 2, trailing newline."""
    return json.dumps(job_json_schema(), sort_keys=True, indent=2, ensure_ascii=False) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m schemas.export", description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="compare instead of writing; exit 1 on a difference")
    parser.add_argument("--path", type=Path, default=SCHEMA_PATH, help=f"schema file (default {SCHEMA_PATH})")
    args = parser.parse_args(argv)
    text = schema_text()
    if args.check:
        current = args.path.read_text(encoding="utf-8") if args.path.exists() else None
        if current != text:
            state = "is missing" if current is None else "is out of date"
            print(f"{args.path} {state}; run `python -m schemas.export`", file=sys.stderr)
            return 1
        print(f"{args.path} is up to date")
        return 0
    args.path.parent.mkdir(parents=True, exist_ok=True)
    args.path.write_text(text, encoding="utf-8")
    print(f"wrote {args.path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
