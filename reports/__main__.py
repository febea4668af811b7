"""Command line: ``python -m reports build [STORE ...] [--out out/report/]``.

With no STORE, every Zarr store under ``out/`` (at any depth: ``paper`` writes ``out/*.zarr``,
``paper --quick`` ``out/quick/*.zarr``); where two hold the same scene the one nearer ``out/`` is
read and the other named.  It prints the stores read, where the report is, and the audit's
counts (the sentence the page opens with).

Exit codes: 0 built; 2 a path was refused (it does not exist, is not a pipeline store, or is a
store of a different or newer format), ``--out`` cannot be written, or bad arguments; nothing is
written then.  Every error is one line on stderr naming the argument.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

from ._audit import audit_summary
from ._build import AUDIT_JSON, build_report, default_stores
from ._read import StoreRefused, open_scene_store
from solver._version import VersionAction

EXIT_REFUSED = 2
#: where ``build`` looks for stores when none is named
DEFAULT_ROOT = "out"


class _UsageError(Exception):
    pass


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit 2, no usage dump
        raise _UsageError(message)


def _parser() -> argparse.ArgumentParser:
    ap = _Parser(prog="python -m reports", description=__doc__.splitlines()[0])
    ap.add_argument("--version", action=VersionAction)
    sub = ap.add_subparsers(dest="command", required=True, parser_class=_Parser)
    b = sub.add_parser("build", help="write index.html, plotly.min.js and audit.json from pipeline stores",
                       description="Build the static offline report from pipeline stores.")
    b.add_argument("stores", nargs="*", metavar="STORE",
                   help=f"Zarr stores (default: every *.zarr under {DEFAULT_ROOT}/, at any depth)")
    b.add_argument("--out", default="out/report", metavar="DIR",
                   help="output directory (default: out/report/)")
    b.add_argument("--no-unrun", action="store_true",
                   help="leave out the shipped scenes that have no store and the paper's figures no store "
                        "draws (default: list them)")
    b.add_argument("--no-audit", action="store_true",
                   help="a report of your own stores: your scenes first, no reproduction audit, no empty "
                        "section (default: the audit when a store of a shipped scene is given, else this)")
    return ap


def _writable(out: Path) -> None:
    """Refuse an output directory that cannot be written, before anything is read or written."""
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=out, prefix=".write-test-"):
            pass
    except OSError as exc:
        raise _UsageError(f"--out: cannot write {out}: {exc.strerror or exc}") from None


def _default_stores(root: str) -> tuple[list[Path], list[str]]:
    """(stores under ``root``, one note per store left out): of two stores of one scene the one
    nearer ``root`` (the full run's ``out/x.zarr`` before ``out/quick/x.zarr``) is read."""
    found = sorted(default_stores(root), key=lambda p: (len(p.parts), str(p)))
    chosen, notes, seen = [], [], {}
    for path in found:
        try:
            name = open_scene_store(path).name
        except StoreRefused as exc:
            notes.append(f"left out {path}: {exc}")
            continue
        if name in seen:
            notes.append(f"left out {path}: scene {name} is read from {seen[name]} (name stores to choose)")
            continue
        seen[name] = path
        chosen.append(path)
    return sorted(chosen), notes


def main(argv=None) -> int:
    try:
        args = _parser().parse_args(argv)
        out = Path(args.out)
        if out.exists() and not out.is_dir():
            raise _UsageError(f"--out: {out} is a file, not a directory")
        stores = [Path(s) for s in args.stores]
        for path in stores:  # one line naming the path, before anything is written
            open_scene_store(path)
        notes = []
        if not stores:
            stores, notes = _default_stores(DEFAULT_ROOT)
            if not stores:
                raise _UsageError(f"STORE: no pipeline store under {DEFAULT_ROOT}/ (run python -m pipeline paper "
                                  "--quick, or name the stores)")
        _writable(out)
    except _UsageError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_REFUSED
    except StoreRefused as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_REFUSED
    for note in notes:
        print(f"reports: {note}", file=sys.stderr)
    t0 = time.perf_counter()
    try:
        index = build_report(stores, out, list_unrun=not args.no_unrun, audit=False if args.no_audit else None)
    except StoreRefused as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_REFUSED
    except OSError as exc:
        print(f"error: --out: cannot write {out}: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_REFUSED
    size = sum(f.stat().st_size for f in index.parent.iterdir() if f.is_file())
    where = "given" if args.stores else f"under {DEFAULT_ROOT}/"
    # build_report reads every path given or refuses them all, so this is the count of stores read
    print(f"stores ({len(stores)} read, {where}): " + (", ".join(os.fspath(p) for p in stores) or "none"), flush=True)
    print(f"report: {index} ({len(stores)} store(s) read, {size / 1e6:.1f} MB, {time.perf_counter() - t0:.1f} s)",
          flush=True)
    audit = index.parent / AUDIT_JSON
    if audit.is_file():
        from ._build import reduced_sentence

        reduced = reduced_sentence([open_scene_store(p) for p in stores])
        print(f"audit: {audit_summary(audit, reduced=reduced)}", flush=True)
    else:
        print("audit: none (a report of your own stores: no store of a shipped scene, or --no-audit)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
