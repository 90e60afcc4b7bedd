"""python -m unispine.conformance --backend NAME|MODULE:FUNCTION [--dtype float64|float32]
[--cases all|NAME...] [--report DIR] [--conventions PRESET] [--timeout S]: exit 0 when every
case passes, 1 when any fails (2 on a usage error)."""

import argparse
import sys

from .backends import BUILTIN
from .conventions import PRESETS
from .runner import run


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m unispine.conformance",
                                 description="Check a rasterizer against the unispine reference.")
    ap.add_argument("--backend", required=True,
                    help=f"a built-in name ({', '.join(sorted(BUILTIN))}) or MODULE:FUNCTION")
    ap.add_argument("--dtype", choices=["float64", "float32"], default="float64")
    ap.add_argument("--cases", nargs="+", default=["all"], help="'all' or case names")
    ap.add_argument("--report", help="folder for summary.md, report.json and reproducers")
    ap.add_argument("--conventions", choices=sorted(PRESETS),
                    help="override the backend's declared conventions")
    ap.add_argument("--timeout", type=float, default=120.0, help="seconds per case")
    a = ap.parse_args(argv)
    try:
        res = run(a.backend, a.dtype, a.cases, a.report, a.timeout, a.conventions)
    except (ValueError, ImportError, AttributeError, TypeError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    sys.stdout.write(res.markdown())
    return res.exit_code


if __name__ == "__main__":
    sys.exit(main())
