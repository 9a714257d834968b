#!/usr/bin/env bash
# Regenerates the CT pictures of docs/ct.md and docs/d2vr.md (docs/images/ct-*.png)
# with the release binary: sinogram, FBP reconstruction, error map, and D²VR next to a
# conventional FDK-then-render pipeline. Usage: scripts/make-ct-figures.sh
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
V=target/release/voxlab
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
I=docs/images

# 1. Parallel beam, scikit-image layout: 256 detector bins of 1 mm, 180 views over 180°.
$V project phantom:shepp-logan-modified --angles 180 --cols 256 \
    --out "$T/sino.npy" --png "$I/ct-sinogram.png"
# 2. FBP (ramp, circle mask) as iradon would, and its error against the exact phantom.
$V reconstruct "$T/sino.npy" --out "$I/ct-fbp.png" \
    --truth phantom:shepp-logan-modified --error-map "$I/ct-fbp-error.png"

# 3. Cone beam: 128 views over 360° of 128² pixels; FDK onto 128³ then a DVR of the
#    grid, against D²VR of the same projections (no grid).
$V project phantom:shepp-logan-modified --geometry cone --angles 128 --cols 128 \
    --rows 128 --du 3 --out "$T/cone.npy"
$V reconstruct "$T/cone.npy" --out "$T/fdk.nrrd"
$V render "$T/fdk.nrrd" --tf phantom --width 256 --height 256 --out "$I/ct-fdk-render.png"
$V d2vr "$T/cone.npy" --geometry "$T/cone.geometry.json" --grid 128 --size 256 \
    --out "$I/ct-d2vr.png"
ls -l "$I"/ct-*.png
