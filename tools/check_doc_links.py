#!/usr/bin/env python3
"""Check that the project's documents point only at files that exist.

Usage (from the repository root): `python3 tools/check_doc_links.py [FILE.md ...]`
(default: `paper_notes.md`, `README.md` and `docs/*.md`).

- Every relative markdown link `[text](target)` must name an existing file or folder, resolved
  from the folder of the document (a `#fragment` is ignored; `http(s)://` and `mailto:` links
  and bare `#anchors` are not checked). A broken link is an error (exit 1).
- Every code-span path such as `src/render/composite.rs`, `render/tiles.rs` or
  `math/{quat,covariance}.rs` (braces expanded) that does not exist relative to the repository
  root, to `src/` or to `python/` is listed as a note, so that renamed or split files do not
  leave stale references behind. Notes do not fail the check: code spans also name files of
  upstream repositories (`src/trainer.py` of SAX-NeRF), which a reader follows there.

Prints one line per problem or note and a summary line.
"""

import glob
import itertools
import os
import re
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LINK = re.compile(r"(?<!!)\[[^\]]*\]\(([^)\s]+)\)")
CODE = re.compile(r"`([^`\n]+)`")
# A path-like code span: words, dots, dashes, slashes and brace lists, with a file extension
# or a trailing slash.
PATHLIKE = re.compile(r"^[A-Za-z0-9_.{},/-]+(\.(rs|py|md|toml|json|yml|yaml|sh|csv)|/)$")
TOP = ("src/", "tests/", "tools/", "docs/", "golden/", "benches/", "python/", ".github/")


def expand(path):
    """`a/{b,c}.rs` -> [`a/b.rs`, `a/c.rs`]."""
    parts = re.split(r"\{([^{}]*)\}", path)
    pieces = [[p] if i % 2 == 0 else p.split(",") for i, p in enumerate(parts)]
    return ["".join(c) for c in itertools.product(*pieces)]


def code_path_ok(path):
    bases = ("", "src", "python")
    return any(os.path.exists(os.path.join(ROOT, b, path)) for b in bases)


def check(doc):
    problems, notes = [], []
    text = open(doc, encoding="utf-8").read()
    here = os.path.dirname(os.path.abspath(doc))
    for n, line in enumerate(text.splitlines(), 1):
        for target in LINK.findall(line):
            if re.match(r"^(https?:|mailto:|#)", target):
                continue
            path = target.split("#", 1)[0]
            if not os.path.exists(os.path.join(here, path)):
                problems.append(f"{doc}:{n}: link to a missing file: {target}")
        for span in CODE.findall(line):
            span = span.strip()
            if not PATHLIKE.match(span) or "/" not in span.rstrip("/"):
                continue
            if not (span.startswith(TOP) or span.split("/")[0] + "/" in
                    [d + "/" for d in os.listdir(os.path.join(ROOT, "src"))]):
                continue
            for p in expand(span):
                if not code_path_ok(p):
                    notes.append(f"{doc}:{n}: note: no such file here (upstream?): {p}")
    return problems, notes


def main():
    os.chdir(ROOT)
    docs = sys.argv[1:] or ["paper_notes.md", "README.md"] + sorted(glob.glob("docs/*.md"))
    results = [check(d) for d in docs]
    problems = [p for r in results for p in r[0]]
    notes = [n for r in results for n in r[1]]
    for line in problems + notes:
        print(line)
    print(f"{len(docs)} documents checked: {len(problems)} broken link(s), {len(notes)} note(s)")
    sys.exit(1 if problems else 0)


if __name__ == "__main__":
    main()
