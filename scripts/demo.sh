#!/usr/bin/env bash
# Main job: built-in spine phantom -> cone-beam projections -> train UniSpine-GS briefly ->
# test PSNR / SSIM. A few minutes on 2 CPU cores. Safe to re-run (outputs are replaced).
#
# Environment overrides: DEMO_DIR (default target/demo), DEMO_ITERS (default 1000),
# DEMO_SIZE (phantom voxels per side, default 64), DEMO_DETECTOR (pixels per side, default 128),
# DEMO_METHOD (default unispine).
set -euo pipefail
cd "$(dirname "$0")/.."

DIR="${DEMO_DIR:-target/demo}"
ITERS="${DEMO_ITERS:-1000}"
SIZE="${DEMO_SIZE:-64}"
DET="${DEMO_DETECTOR:-128}"
METHOD="${DEMO_METHOD:-unispine}"

echo "== building the release binary"
cargo build --release --quiet
BIN=target/release/unispine

mkdir -p "$DIR"
echo "== phantom dataset: ${SIZE}^3 voxels, ${DET}x${DET} detector, 50 train / 50 test views -> $DIR/phantom"
"$BIN" data phantom --size "$SIZE" --detector "$DET" --out "$DIR/phantom"

echo "== training '$METHOD' for $ITERS iterations (paper schedule compressed from 20000) -> $DIR/run-$METHOD"
"$BIN" train --data "$DIR/phantom" --method "$METHOD" --iters "$ITERS" --compress-schedule \
    --out "$DIR/run-$METHOD"

echo
echo "== results"
python_free_summary() {
    # Print the final test metrics from metrics.json without needing python or jq.
    grep -E '"(test_psnr|test_ssim|n_gaussians|train_time_s|render_fps)"' "$1" | sed 's/^ */  /'
}
python_free_summary "$DIR/run-$METHOD/metrics.json"
"$BIN" report "$DIR/run-$METHOD" --charts "$DIR/charts" > "$DIR/report.md"
echo "outputs: $DIR/run-$METHOD (config.json, metrics.json, log.csv, model.ply, previews/*.png)"
echo "dataset: $DIR/phantom"
echo "report:  $DIR/report.md, charts: $DIR/charts/{tradeoff,curves}.svg"
