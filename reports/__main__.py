"""Command line: ``python -m reports build [STORE ...] --out out/report/``.

Exit codes: 0 built; 2 a path was refused (it does not exist, is not a pipeline store, or is a
store of a different or newer format) or bad arguments; nothing is written then.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ._audit import audit_summary
from ._build import AUDIT_JSON, build_report, default_stores
from ._read import StoreRefused
from solver._version import VersionAction

EXIT_REFUSED = 2


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m reports", description=__doc__.splitlines()[0])
    ap.add_argument("--version", action=VersionAction)
    sub = ap.add_subparsers(dest="command", required=True)
    b = sub.add_parser("build", help="write index.html and plotly.min.js from pipeline stores")
    b.add_argument("stores", nargs="*", help="Zarr stores (default: every *.zarr under out/)")
    b.add_argument("--out", default="out/report", help="output directory (default out/report/)")
    b.add_argument("--no-unrun", action="store_true", help="do not list shipped scenes that have no store")
    return ap


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    stores = [Path(s) for s in args.stores] or default_stores("out")
    t0 = time.perf_counter()
    try:
        index = build_report(stores, args.out, list_unrun=not args.no_unrun)
    except StoreRefused as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_REFUSED
    size = sum(f.stat().st_size for f in index.parent.iterdir() if f.is_file())
    # build_report reads every path given or refuses them all, so this is the count of stores read
    print(f"report: {index} ({len(stores)} store(s) read, {size / 1e6:.1f} MB, {time.perf_counter() - t0:.1f} s)",
          flush=True)
    print(f"audit: {audit_summary(index.parent / AUDIT_JSON)}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
