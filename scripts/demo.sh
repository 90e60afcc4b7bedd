#!/usr/bin/env bash
# Main job: `unispine reproduce quick`: a small Table 2 (3DGS, X-Gaussian, UniSpine-GS, 2 seeds)
# on the built-in spine phantom, with verdicts on the paper's claims, report.html and charts.
# A few minutes on 2 CPU cores. Safe to re-run: finished cells are kept.
#
# Environment overrides: DEMO_DIR (default target/demo), DEMO_PLAN (default quick; any
# built-in plan name or plan TOML file), DEMO_JOBS (cells run at once, default 1).
set -euo pipefail
cd "$(dirname "$0")/.."

DIR="${DEMO_DIR:-target/demo}"
PLAN="${DEMO_PLAN:-quick}"
JOBS="${DEMO_JOBS:-1}"

echo "== building the release binary"
cargo build --release --quiet
BIN=target/release/unispine

echo "== unispine reproduce $PLAN --out $DIR/$PLAN --jobs $JOBS"
"$BIN" reproduce "$PLAN" --out "$DIR/$PLAN" --jobs "$JOBS"
