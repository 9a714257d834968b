#!/usr/bin/env bash
# The pictures of docs/view.md: screenshots of `voxlab view` under a virtual X server
# (xvfb-run, with lavapipe or a GPU), and `voxlab render --state` of edited states for
# the teaching tour. Run from anywhere: bash scripts/docs_view.sh
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release
V=target/release/voxlab
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
IMG=docs/images
view() { xvfb-run -a -s "-screen 0 1400x900x24" "$V" view "$@"; }
# edit STATE OUT PYTHON: writes STATE with `s` (the parsed JSON) changed by PYTHON.
edit() {
    python3 - "$1" "$2" "$3" <<'EOF'
import json, sys
s = json.load(open(sys.argv[1]))
exec(sys.argv[3])
json.dump(s, open(sys.argv[2], "w"), indent=1)
EOF
}

# The lab as it opens: the embedded micro-CT of bone on the GPU.
view --frames 3 --window-screenshot "$IMG/view-default.png" --save-state "$T/default.json"
# The difference view: the GPU frame against the CPU f64 oracle.
view --state "$T/default.json" --frames 3 --compare --window-screenshot "$IMG/view-compare.png"
# A 2-D transfer function over the value × gradient-magnitude histogram.
edit "$T/default.json" "$T/2d.json" \
    's["settings"]["transfer_2d"] = json.load(open("data/tf/microct-bone-2d.json"))'
view --state "$T/2d.json" --frames 3 --window-screenshot "$IMG/view-2d.png"

# The teaching tour: one change each, rendered with `voxlab render --state`.
small='s["width"] = s["height"] = 320'
edit "$T/default.json" "$T/tour.json" "$small"
"$V" render --state "$T/tour.json" --out "$IMG/view-tour-base.png"
edit "$T/tour.json" "$T/step.json" 's["settings"]["step"] = 4.0'
"$V" render --state "$T/step.json" --out "$IMG/view-tour-step4.png"
edit "$T/tour.json" "$T/pre.json" 's["settings"]["classification"] = "pre"'
"$V" render --state "$T/pre.json" --out "$IMG/view-tour-pre.png"
edit "$T/tour.json" "$T/nearest.json" 's["settings"]["filter"] = "nearest"'
"$V" render --state "$T/nearest.json" --out "$IMG/view-tour-nearest.png"
"$V" render --state "$T/tour.json" --out "$T/x.png" --samples "$IMG/view-tour-samples-ert.png"
edit "$T/tour.json" "$T/noert.json" 's["settings"]["ert_threshold"] = 1.0'
"$V" render --state "$T/noert.json" --out "$T/y.png" --samples "$IMG/view-tour-samples-noert.png"
echo "wrote $IMG/view-*.png"
