#!/usr/bin/env bash
# Fuzzes voxlab's file readers with libFuzzer through cargo-fuzz: every target in
# fuzz/fuzz_targets for SECONDS each (default 60), seeded from tests/corpus/seeds.
# Crashes land in fuzz/artifacts/<target>/; add each one, once fixed, to
# tests/corpus/broken/ with its expected error.
#
#   cargo install cargo-fuzz
#   bash scripts/fuzz.sh            # 60 s per target
#   bash scripts/fuzz.sh 600 nifti  # 10 minutes on one target
set -euo pipefail
cd "$(dirname "$0")/.."
secs=${1:-60}
shift || true
targets=${*:-nrrd npy nifti pvm den metaimage dicom rtk_geometry astra_geometry}
if ! cargo fuzz --version >/dev/null 2>&1; then
    echo "fuzz.sh: cargo-fuzz is missing: cargo install cargo-fuzz" >&2
    exit 1
fi
# cargo-fuzz passes nightly-only sanitizer flags; this lets a stable rustc take them.
export RUSTC_BOOTSTRAP=1
for t in $targets; do
    mkdir -p "fuzz/corpus/$t"
    seeds=()
    [ -d "tests/corpus/seeds/$t" ] && seeds=("tests/corpus/seeds/$t")
    # DICOM's seeds are the decoder fixtures, whose values the tests check.
    [ "$t" = dicom ] && seeds=("tests/data/dicom")
    echo "fuzz.sh: $t for ${secs}s"
    cargo fuzz run "$t" "fuzz/corpus/$t" "${seeds[@]}" -- \
        -max_total_time="$secs" -rss_limit_mb=2048 -max_len=262144 -timeout=10
done
