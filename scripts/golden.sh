#!/usr/bin/env bash
# Fingerprints what the `voxlab` command line writes: the demo pictures and a few dozen
# renders, reconstructions, projections, FVR images, processed volumes and FFT checks,
# each as a SHA-256 of its output files, plus every command's messages with times
# blanked out. Run it before and after a change that must not change behaviour:
#
#   bash scripts/golden.sh record golden.txt [BIN]   # BIN defaults to target/release/voxlab
#   bash scripts/golden.sh check  golden.txt [BIN]   # exit 1 and a diff on any difference
#
# GPU cases run when an adapter exists (lavapipe included; set VOXLAB_ADAPTER to pick
# one). Their lines start with `gpu/`, so a CPU-only machine checks the rest; a change
# of adapter or driver may change them by rounding.
set -euo pipefail
mode=${1:?usage: golden.sh record|check FILE [BIN]}
file=${2:?usage: golden.sh record|check FILE [BIN]}
here=$(cd "$(dirname "$0")/.." && pwd)
bin=${3:-$here/target/release/voxlab}
bin=$(cd "$(dirname "$bin")" && pwd)/$(basename "$bin")
[ -x "$bin" ] || { echo "golden.sh: no binary $bin (cargo build --release)"; exit 2; }
case "$file" in /*) ;; *) file=$PWD/$file ;; esac

work=$(mktemp -d "${TMPDIR:-/tmp}/voxlab-golden.XXXXXX")
# GOLDEN_KEEP=1 keeps the outputs and messages for a look at what differs.
if [ "${GOLDEN_KEEP:-0}" = 1 ]; then
    trap 'echo "golden.sh: outputs kept in $work"' EXIT
else
    trap 'rm -rf "$work"' EXIT
fi
cd "$work"
out=$work/fingerprints.txt
: >"$out"

gpu=0
if "$bin" info --gpu >/dev/null 2>&1; then gpu=1; fi

# Messages with every duration and throughput blanked (and every number printed with
# exactly three decimals, the format of timings), and the scratch path removed.
scrub() {
    sed -E -e "s#$work/##g" \
        -e 's/[0-9]+(\.[0-9]+)?(e-?[0-9]+)? ?(s|ms|µs|us|GFLOP\/s|GB\/s|Gvox\/s)\b/T/g' \
        -e 's/(elapsed|eta) [^ )]*/\1 T/g' \
        -e 's/\b[0-9]+\.[0-9]{3}\b/T/g' \
        -e 's/[0-9]+ CPU threads/N CPU threads/g'
}

# case NAME FILES... -- ARGS...: runs voxlab ARGS, then fingerprints the status, the
# messages and each file (a folder: every file in it, by name).
case_() {
    local name=$1
    shift
    local files=()
    while [ "$1" != "--" ]; do files+=("$1"); shift; done
    shift
    mkdir -p "$work/$name"
    local status=0
    if [ "$1" = sh ]; then
        (cd "$work/$name" && "$@" >stdout.txt 2>stderr.txt) || status=$?
    else
        (cd "$work/$name" && "$bin" "$@" >stdout.txt 2>stderr.txt) || status=$?
    fi
    {
        echo "$name status $status"
        echo "$name stdout $(scrub <"$work/$name/stdout.txt" | sha256sum | cut -c1-16)"
        echo "$name stderr $(scrub <"$work/$name/stderr.txt" | sha256sum | cut -c1-16)"
        local f p
        for f in "${files[@]}"; do
            p=$work/$name/$f
            if [ -d "$p" ]; then
                (cd "$p" && find . -type f | sort | while read -r g; do
                    echo "$name $f/${g#./} $(strip_json "$g" | sha256sum | cut -c1-16)"
                done)
            elif [ -f "$p" ]; then
                echo "$name $f $(strip_json "$p" | sha256sum | cut -c1-16)"
            else
                echo "$name $f MISSING"
            fi
        done
    } >>"$out"
}

# JSON reports carry timings; keep everything else.
strip_json() {
    case "$1" in
        *.json) python3 - "$1" <<'EOF'
import json, sys
TIMING = ("second", "time", "_ms", "_s", "gflops", "gbps", "adapter", "date", "elapsed")
def strip(v):
    if isinstance(v, dict):
        return {k: strip(x) for k, x in v.items()
                if not any(t in k.lower() for t in TIMING) and k.lower() not in ("total", "setup", "upload", "prepare", "kernel", "readback", "kernel_from_timestamps")}
    if isinstance(v, list):
        return [strip(x) for x in v]
    return v
print(json.dumps(strip(json.load(open(sys.argv[1]))), sort_keys=True))
EOF
        ;;
        *) cat "$1" ;;
    esac
}

p64=phantom:shepp-logan-modified:64
sp=phantom:spheres:48

# The gallery (the main job).
case_ demo gallery -- demo --out gallery

# Renders on the oracle and the f32 path.
case_ render-dvr a.png s.npy -- render $p64 --width 96 --height 80 --samples s.npy --out a.png
case_ render-dvr16 a.png -- render $p64 --width 64 --height 64 --sixteen-bit --filter catmull-rom --out a.png
case_ render-dvr-f32 a.npy -- render $p64 --width 64 --height 64 --backend cpu-f32 --out a.npy
case_ render-mip a.png s.png -- render $sp --mode mip --ortho --backend cpu-f32 --samples s.png --width 64 --height 64 --out a.png
case_ render-xray a.npy -- render $p64 --mode xray --view +z --step 1 --out a.npy
case_ render-minip a.npy -- render $sp --mode minip --view -x --window 0.5,0.4 --out a.npy
case_ render-mida a.png -- render $p64 --mode mida --mida-gamma 0.3 --width 64 --height 64 --out a.png
case_ render-iso a.png -- render phantom:sphere:40 --mode iso --iso 0.5:#ff8000:0.6 --iso 0.2:#0080ff:0.3 --width 64 --height 64 --out a.png
case_ render-iso-opaque a.png -- render phantom:sphere:40 --mode iso --iso 0.5:#ff8000:1 --iso-opaque --shadows --light 1,1,1 --width 64 --height 64 --out a.png
case_ render-pre-b2f a.npy -- render $p64 --classification pre --compositing back-to-front --gradient sobel --precompute-gradients --width 48 --height 48 --out a.npy
case_ render-filters a.npy -- render phantom:marschner-lobb:24 --filter lanczos3 --tf marschner-lobb --width 48 --height 48 --out a.npy
case_ render-bspline a.npy -- render phantom:marschner-lobb:24 --filter cubic-bspline-fast-interp --tf marschner-lobb --width 48 --height 48 --out a.npy
case_ render-tf2d a.png -- render $p64 --tf2d ct-bone-2d --gradient-axis log --faux-shading 1.5 --width 64 --height 64 --out a.png
case_ render-tf-preset a.png -- render $p64 --tf-preset ct-bone --window 2000 --level 500 --width 48 --height 48 --out a.png
case_ render-stereo a.png -- render $p64 --stereo anaglyph --eye-separation 40 --width 64 --height 48 --out a.png
case_ render-stereo-sbs a.png -- render $p64 --stereo side-by-side --width 48 --height 48 --out a.png
case_ render-accumulate a.npy -- render $p64 --jitter 3 --accumulate 3 --width 48 --height 48 --out a.npy
case_ render-interleaved a.npy -- render $p64 --interleaved --skip-empty off --width 48 --height 48 --out a.npy
case_ render-clipbox a.npy -- render $p64 --clip-box 10,10,10,50,50,40 --block-size 8 --width 48 --height 48 --out a.npy
case_ render-clipmesh a.npy -- render $p64 --clip-mesh bricks --width 48 --height 48 --out a.npy
case_ render-repeat a.npy -- render $p64 --repeat 2 --width 32 --height 32 --out a.npy
case_ render-adaptive a.png s.png -- render $p64 --sampling adaptive --no-shading --samples s.png --width 48 --height 48 --out a.png
case_ render-multi a.npy -- render $p64 --volume $sp --transform 1,0,0,10,0,1,0,0,0,0,1,0 --volume-tf phantom --width 48 --height 48 --out a.npy
case_ render-settings a.npy -- render $sp --settings /dev/null --out a.npy
case_ render-bad-window a.png -- render $p64 --window 0,3 --out a.png

# Files: phantom, info, convert, slice, tf.
case_ phantom vol.nrrd vol.nii.gz vol.npy -- sh -c "\"$bin\" phantom ellipsoid:20,16,12 --out vol.nrrd && \"$bin\" phantom marschner-lobb:16 --out vol.nii.gz && \"$bin\" phantom sphere:12 --out vol.npy"
case_ info-json -- info phantom:spheres:32 --json
case_ info-text h.png -- info phantom:shepp-logan:32 --bins 8 --plot h.png
case_ convert c.nrrd r.npy -- sh -c "\"$bin\" convert phantom:shepp-logan:32 c.nrrd --crop 2,2,2,30,28,26 --type u16 && \"$bin\" convert phantom:sphere:20 r.npy --resize 12,14,16 --filter catmull-rom"
case_ slice z.png x.npy -- sh -c "\"$bin\" slice phantom:shepp-logan:32 --axis z --out z.png --sixteen-bit && \"$bin\" slice phantom:shepp-logan:32 --axis x --index 5 --window 0.4 --level 0.3 --out x.npy"
case_ tf -- tf
case_ tf-one -- tf ct-bone

# CT: projection, reconstruction, D²VR.
case_ project-par p.npy p.geometry.json p.png -- project phantom:shepp-logan:64 --cols 64 --angles 45 --png p.png --out p.npy
case_ project-cone p.npy p.geometry.json -- project phantom:shepp-logan:32 --geometry cone --cols 48 --rows 40 --angles 24 --du 8 --out p.npy
case_ project-joseph p.nrrd -- project phantom:shepp-logan:32 --method joseph --backend cpu-f32 --cols 48 --angles 30 --out p.nrrd
case_ recon-fbp r.npy e.png -- sh -c "\"$bin\" project phantom:shepp-logan:64 --cols 64 --angles 60 --out p.npy >/dev/null && \"$bin\" reconstruct p.npy --filter shepp-logan --truth phantom:shepp-logan --error-map e.png --out r.npy"
case_ recon-fbp-f32 r.png -- sh -c "\"$bin\" project phantom:shepp-logan:64 --cols 64 --angles 60 --out p.npy >/dev/null && \"$bin\" reconstruct p.npy --backend cpu-f32 --no-circle --out r.png"
case_ recon-parallel r.npy -- sh -c "\"$bin\" project phantom:shepp-logan:64 --cols 64 --angles 40 --out p.npy >/dev/null && mv p.geometry.json g.json && \"$bin\" reconstruct p.npy --geometry parallel --angles 40 --size 48 --out r.npy"
case_ recon-fdk r.nrrd -- sh -c "\"$bin\" project phantom:shepp-logan:32 --geometry cone --cols 48 --rows 48 --angles 36 --du 8 --out p.npy >/dev/null && \"$bin\" reconstruct p.npy --size 32 --filter hann --out r.nrrd"
case_ recon-short r.npy -- sh -c "\"$bin\" project phantom:shepp-logan:32 --geometry cone --cols 48 --rows 48 --angles 40 --range 220 --du 8 --out p.npy >/dev/null && \"$bin\" reconstruct p.npy --size 24 --short-scan --out r.npy"
case_ d2vr a.png -- d2vr phantom:shepp-logan-modified --angles 32 --detector 48 --grid 32 --size 48 --out a.png
case_ d2vr-mip a.npy -- d2vr phantom:shepp-logan-modified --beam parallel --angles 24 --detector 32 --grid 24 --size 32 --mode mip --gradient gfs --occupancy --out a.npy

# Fourier volume rendering and the FFT check.
case_ fvr a.npy -- fvr phantom:shepp-logan:32 --kernel lanczos3 --out a.npy
case_ fvr-f32 a.png -- fvr phantom:shepp-logan:32 --backend cpu-f32 --kernel trilinear --deapodize --view +y --out a.png
case_ fvr-dirichlet a.npy -- fvr phantom:sphere:8 --kernel dirichlet --padding 1 --out a.npy
case_ fft r.json -- fft 64 16x8 4x4x4 --backend cpu --runs 1 --json r.json

# Processing.
case_ process-resample a.nrrd -- process phantom:shepp-logan:24 --op resample --dims 16,18,20 --filter lanczos3 --out a.nrrd
case_ process-resample-world a.npy -- process phantom:shepp-logan:24 --op resample --spacing 12 --world-box=-100,-100,-100,100,100,100 --backend cpu-f32 --out a.npy
case_ process-gaussian a.nii -- process phantom:shepp-logan:24 --op gaussian --sigma 1,1.5,2 --out a.nii
case_ process-median a.npy -- process phantom:shepp-logan:24 --op median --size 3 --out a.npy
case_ process-gradient a.npy -- process phantom:shepp-logan:24 --op gradient-magnitude --backend cpu-f32 --out a.npy

# Adaptive sampling side by side, and the bench's case list.
case_ adaptive out/table.json out/regular.png out/adaptive.png out/direct.png -- adaptive phantom:shepp-logan-modified:32 --size 48 --runs 1 --out out
case_ bench-list -- bench --suite quick --list

# Errors a user meets: the message and the status.
case_ err-missing -- render no-such-file.nrrd --out a.png
case_ err-ext -- render $p64 --out a.jpg
case_ err-backend -- fvr $p64 --backend tpu --out a.png
case_ err-recon -- reconstruct no-such.npy --out r.npy

if [ "$gpu" = 1 ]; then
    case_ gpu/render a.npy -- render $p64 --backend gpu --width 48 --height 48 --out a.npy
    case_ gpu/render-mip a.npy -- render $sp --backend gpu --mode mip --view +z --out a.npy
    case_ gpu/render-hw a.npy -- render $p64 --backend gpu --hardware-filtering --width 48 --height 48 --out a.npy
    case_ gpu/compare cmp/cpu.png cmp/gpu.png cmp/diff.png -- compare $sp --mode mip --ortho --width 48 --height 48 --out-dir cmp --max-abs 1e-4
    case_ gpu/project p.npy -- project phantom:shepp-logan:32 --method joseph --backend gpu --cols 48 --angles 30 --out p.npy
    case_ gpu/recon r.npy -- sh -c "\"$bin\" project phantom:shepp-logan:64 --cols 64 --angles 60 --out p.npy >/dev/null && \"$bin\" reconstruct p.npy --backend gpu --out r.npy"
    case_ gpu/fdk r.npy -- sh -c "\"$bin\" project phantom:shepp-logan:32 --geometry cone --cols 48 --rows 48 --angles 36 --du 8 --out p.npy >/dev/null && \"$bin\" reconstruct p.npy --size 32 --backend gpu --out r.npy"
    case_ gpu/d2vr a.png -- d2vr phantom:shepp-logan-modified --angles 32 --detector 48 --grid 32 --size 48 --backend gpu --out a.png
    case_ gpu/fvr a.npy -- fvr phantom:shepp-logan:32 --backend gpu --out a.npy
    case_ gpu/process a.npy -- process phantom:shepp-logan:24 --op gaussian --sigma 1 --backend gpu --out a.npy
    case_ gpu/resample a.npy -- process phantom:shepp-logan:24 --op resample --dims 16,16,16 --filter lanczos3 --backend gpu --out a.npy
    case_ gpu/adaptive out/table.json out/adaptive.png -- adaptive phantom:shepp-logan-modified:32 --size 48 --runs 1 --backend gpu --out out
    case_ gpu/fft r.json -- fft 64 16x8 4x4x4 --backend gpu --runs 1 --json r.json
fi

case "$mode" in
    record)
        cp "$out" "$file"
        echo "golden.sh: $(wc -l <"$out") fingerprints written to $file"
        ;;
    check)
        if diff -u "$file" "$out"; then
            echo "golden.sh: all $(wc -l <"$out") fingerprints match $file"
        else
            echo "golden.sh: fingerprints differ from $file (above: - recorded, + now)"
            exit 1
        fi
        ;;
    *) echo "golden.sh: record or check, not '$mode'"; exit 2 ;;
esac
