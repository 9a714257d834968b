#!/usr/bin/env bash
# The picture of docs/distributed.md: FDK of the modified Shepp–Logan phantom on four
# MPI ranks (a build with feature `mpi`), checked byte for byte against one process.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --features mpi --bin voxlab
V=target/release/voxlab
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
$V project phantom:shepp-logan-modified --geometry cone --angles 240 --cols 160 \
    --rows 160 --du 2.4 --out "$T/sl.npy"
OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 \
    mpirun --oversubscribe -n 4 $V reconstruct "$T/sl.npy" --size 128 \
    --out "$T/four.npy" --distributed
$V reconstruct "$T/sl.npy" --size 128 --out "$T/one.npy"
cmp "$T/one.npy" "$T/four.npy" && echo "four ranks = one process, byte for byte"
$V slice "$T/four.npy" --axis x --window 0.5 --level 0.25 \
    --out docs/images/distributed-fdk-x.png

# The picture of the rendering section: the embedded micro-CT, read brick by brick
# from a raw .npy by four ranks; the MIP of the same on four ranks is checked byte for
# byte against one process.
$V convert embedded:microct-bone "$T/bone.npy"
OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 \
    mpirun --oversubscribe -n 4 $V render "$T/bone.npy" --tf microct-bone --width 400 \
    --height 400 --out docs/images/distributed-render.png --distributed
OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 \
    mpirun --oversubscribe -n 4 $V render "$T/bone.npy" --mode mip --out "$T/mip4.npy" \
    --distributed
$V render "$T/bone.npy" --mode mip --out "$T/mip1.npy"
cmp "$T/mip1.npy" "$T/mip4.npy" && echo "MIP: four ranks = one process, byte for byte"
