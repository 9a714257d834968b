#!/usr/bin/env bash
# GPU checks on a machine that has a GPU but no Rust toolchain (and no network).
#
#   bash scripts/gpu_bundle.sh pack [main|tests]...   # here, with cargo
#   bash scripts/gpu_bundle.sh run  [bench|fft|d2vr|cufft|tests]... # there, in a copy of the repo
#
# pack builds release programs, strips them and compresses them into
# target/gpu-bundle/<part>.tar.xz (copy that folder with the repository):
#   main   target/release/voxlab and the `fft` and `d2vr` cargo bench programs (about
#          9 MB);
#   tests  the GPU and CLI test programs, tests/gpu_*.rs and tests/cli_*.rs (about 21 MB;
#          the CLI tests run main's voxlab).
# Without arguments it packs both.
#
# run unpacks whatever parts are there into target/ and writes every result under
# $VOXLAB_BUNDLE_OUT (default target/gpu-bundle-out):
#   bench  `voxlab bench --suite full` on the GPU (--require-gpu) -> <adapter>.md/.json/.svg
#   fft    `cargo bench --bench fft`'s program                     -> fft-bench.txt
#   d2vr   `cargo bench --bench d2vr`'s program (shaded D²VR, exact, f16 and from
#          textures, each one's error against the CPU; a few minutes, most of them the
#          CPU's: VOXLAB_BENCH_RUNS=1 shortens it)                -> d2vr-bench.txt
#   cufft  scripts/peers/gpu_fft_peers.py (needs CuPy)             -> cufft.json, cufft.md
#   tests  every packed test program, 8 threads, 180 s each        -> tests.txt (a table)
#          (VOXLAB_BUNDLE_TESTS='gpu_fft*' picks programs by name)
# Without arguments it runs bench, fft and cufft. The test programs were compiled with
# this checkout's absolute path; where that path does not exist there, run links it to
# the copy it runs in, so that the tests find their fixtures and the voxlab binary.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
bundle=target/gpu-bundle

# The executables cargo reports for a build (`--message-format=json`).
executables() {
    python3 -c '
import json, sys
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m.get("executable"):
        print(m["executable"])'
}

pack_part() {
    local part=$1 stage
    stage=$(mktemp -d)
    trap 'rm -rf "$stage"' RETURN
    mkdir -p "$stage/release/deps" "$bundle"
    case $part in
    main)
        cargo build --release --bin voxlab
        strip -o "$stage/release/voxlab" target/release/voxlab
        for b in fft d2vr; do
            cargo bench --no-run --bench "$b" --message-format=json 2>/dev/null | executables |
                while read -r exe; do strip -o "$stage/release/$b-bench" "$exe"; done
        done
        ;;
    tests)
        local args=()
        for f in tests/gpu_*.rs tests/cli_*.rs; do
            args+=(--test "$(basename "$f" .rs)")
        done
        # The test programs alone (cargo also reports the voxlab binary they use).
        cargo test --release --no-run "${args[@]}" --message-format=json 2>/dev/null |
            executables | grep '/deps/' | while read -r exe; do
            strip -o "$stage/release/deps/$(basename "$exe")" "$exe"
        done
        ;;
    *)
        echo "gpu_bundle.sh pack: unknown part '$part' (main, tests)" >&2
        exit 2
        ;;
    esac
    echo "$root" >"$stage/release/built-in"
    tar -C "$stage" -cf - release | xz -9 -T0 >"$bundle/$part.tar.xz.part"
    mv "$bundle/$part.tar.xz.part" "$bundle/$part.tar.xz"
    echo "packed $bundle/$part.tar.xz ($(du -h "$bundle/$part.tar.xz" | cut -f1))"
}

run_tests() {
    local out=$1 built
    built=$(cat target/release/built-in)
    if [ "$built" != "$root" ] && [ ! -e "$built" ]; then
        mkdir -p "$(dirname "$built")"
        ln -s "$root" "$built"
    fi
    {
        echo "| program | result | wall time |"
        echo "|---|---|---|"
    } >"$out/tests.txt"
    for exe in target/release/deps/${VOXLAB_BUNDLE_TESTS:-*}; do
        [ -x "$exe" ] || continue
        local name start rc log
        name=$(basename "$exe" | sed 's/-[0-9a-f]*$//')
        log="$out/test-$name.log"
        start=$(date +%s)
        rc=0
        timeout 180 "$exe" --test-threads 8 >"$log" 2>&1 || rc=$?
        local summary
        summary=$(grep -o 'test result: .*' "$log" | tail -1 | sed 's/; finished.*//')
        [ $rc -eq 124 ] && summary="stopped at the 180 s limit"
        echo "| \`$name\` | ${summary:-exit $rc} | $(($(date +%s) - start)) s |" >>"$out/tests.txt"
    done
    cat "$out/tests.txt"
}

cmd=${1:-}
shift || true
case $cmd in
pack)
    parts=("$@")
    [ ${#parts[@]} -gt 0 ] || parts=(main tests)
    for p in "${parts[@]}"; do pack_part "$p"; done
    ;;
run)
    out=${VOXLAB_BUNDLE_OUT:-target/gpu-bundle-out}
    mkdir -p "$out" target
    for t in "$bundle"/*.tar.xz; do
        [ -e "$t" ] && xz -dc "$t" | tar -C target -xf -
    done
    what=("$@")
    [ ${#what[@]} -gt 0 ] || what=(bench fft cufft)
    for w in "${what[@]}"; do
        echo "== $w"
        case $w in
        bench) target/release/voxlab bench --suite full --require-gpu --out "$out" ;;
        fft) target/release/fft-bench --bench 2>&1 | tee "$out/fft-bench.txt" ;;
        d2vr) target/release/d2vr-bench --bench 2>&1 | tee "$out/d2vr-bench.txt" ;;
        cufft)
            python3 scripts/peers/gpu_fft_peers.py --runs 20 --out "$out/cufft.json" |
                tee "$out/cufft.md"
            ;;
        tests) run_tests "$out" ;;
        *)
            echo "gpu_bundle.sh run: unknown step '$w' (bench, fft, d2vr, cufft, tests)" >&2
            exit 2
            ;;
        esac
    done
    ;;
*)
    sed -n '2,27p' "$0" | sed 's/^# \{0,1\}//'
    [ "$cmd" = "-h" ] || [ "$cmd" = "--help" ] || exit 2
    ;;
esac
