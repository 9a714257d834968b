#!/usr/bin/env bash
# The test command: runs voxlab's whole test suite in release mode.
#
# GPU tests need a Vulkan (or Metal/DX12) adapter. When none is found and this runs as
# root on a Debian/Ubuntu machine, Mesa's software Vulkan driver (lavapipe, package
# mesa-vulkan-drivers) is installed first, so the GPU tests really run; likewise Xvfb for
# the lab's window test. Without an
# adapter they fail, unless VOXLAB_ALLOW_NO_GPU=1, in which case they say loudly that
# they skipped.
set -euo pipefail
cd "$(dirname "$0")/.."

have_vulkan_driver() {
    # A Vulkan loader and at least one installable client driver (ICD) manifest.
    # (No `grep -q` in pipes: under pipefail its early exit kills the writer.)
    local loader icds
    loader=$(ldconfig -p 2>/dev/null | grep -c 'libvulkan\.so\.1' || true)
    icds=$(ls /usr/share/vulkan/icd.d/*.json /etc/vulkan/icd.d/*.json \
           /usr/local/share/vulkan/icd.d/*.json 2>/dev/null | wc -l)
    [ "${loader:-0}" -gt 0 ] && [ "${icds:-0}" -gt 0 ]
}

if [ "$(uname -s)" = "Linux" ] && ! have_vulkan_driver; then
    if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
        echo "test.sh: no Vulkan driver found; installing mesa-vulkan-drivers (lavapipe)…"
        export DEBIAN_FRONTEND=noninteractive
        apt-get update -qq
        apt-get install -y -qq --no-install-recommends mesa-vulkan-drivers libvulkan1 >/dev/null
    else
        echo "test.sh: no Vulkan driver found and cannot install one (needs root and apt-get)."
        echo "test.sh: install mesa-vulkan-drivers, or set VOXLAB_ALLOW_NO_GPU=1 to skip GPU tests."
    fi
fi

# The lab's window test (tests/lab_window.rs) needs an X server: without $DISPLAY, a
# virtual one (Xvfb through xvfb-run), and the X11 client libraries the window loads.
have_x11_libs() {
    local n
    n=$(ldconfig -p 2>/dev/null | grep -c 'libxkbcommon-x11\.so\.0\|libXcursor\.so\.1\|libXi\.so\.6\|libXrandr\.so\.2' || true)
    [ "${n:-0}" -ge 4 ]
}
if [ "$(uname -s)" = "Linux" ] && { { [ -z "${DISPLAY:-}" ] && ! command -v xvfb-run >/dev/null 2>&1; } || ! have_x11_libs; }; then
    if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
        echo "test.sh: installing Xvfb and the X11 libraries for the lab's window test…"
        export DEBIAN_FRONTEND=noninteractive
        apt-get update -qq
        apt-get install -y -qq --no-install-recommends xvfb xauth libxkbcommon-x11-0 \
            libxcursor1 libxrandr2 libxi6 libx11-xcb1 >/dev/null
    else
        echo "test.sh: no X server and cannot install Xvfb (needs root and apt-get):"
        echo "test.sh: install xvfb, xauth and libxkbcommon-x11-0, or the lab's window test fails."
    fi
fi

# Mesa complains when XDG_RUNTIME_DIR is unset; give it a private one.
if [ -z "${XDG_RUNTIME_DIR:-}" ]; then
    export XDG_RUNTIME_DIR="${TMPDIR:-/tmp}/voxlab-xdg-$(id -u)"
    mkdir -p "$XDG_RUNTIME_DIR" && chmod 700 "$XDG_RUNTIME_DIR"
fi

rm -f target/gpu-tests-skipped.txt
cargo test --release --all-targets "$@"
cargo test --release --doc

# The Python package (python/): a virtual environment under target/, the package built
# by pip (maturin, release, sharing the target directory with the cargo build above)
# and its tests (python/tests: against numpy.fft, scikit-image and the command line
# built above; GPU tests follow the same no-adapter rule).
PYTHON=${PYTHON:-python3}
VENV=target/py-venv
if [ ! -x "$VENV/bin/python" ]; then
    if ! "$PYTHON" -m venv "$VENV" 2>/dev/null; then
        rm -rf "$VENV"
        if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
            echo "test.sh: '$PYTHON -m venv' failed; installing python3-venv…"
            export DEBIAN_FRONTEND=noninteractive
            apt-get update -qq
            apt-get install -y -qq --no-install-recommends python3-venv python3-pip >/dev/null
            "$PYTHON" -m venv "$VENV"
        else
            echo "test.sh: '$PYTHON -m venv' failed: install Python's venv module (python3-venv)."
            exit 1
        fi
    fi
fi
"$VENV/bin/python" -m pip install -q --disable-pip-version-check -r python/requirements-test.txt
"$VENV/bin/python" -m pip install -q --disable-pip-version-check --force-reinstall --no-deps ./python
"$VENV/bin/python" -m pytest -q -p no:cacheprovider python/tests

# The distributed reconstruction and render under MPI (feature `mpi`;
# tests/mpi_reconstruct.rs, tests/mpi_render.rs):
# OpenMPI's mpirun and library, and libclang for the mpi crate's bindings, installed
# through apt when missing and this runs as root. Without them these tests fail,
# unless VOXLAB_ALLOW_NO_MPI=1, in which case they say loudly that they skipped.
have_mpi() {
    local clang
    clang=$(ldconfig -p 2>/dev/null | grep -c 'libclang' || true)
    command -v mpirun >/dev/null 2>&1 && command -v mpicc >/dev/null 2>&1 \
        && [ "${clang:-0}" -gt 0 ]
}
if ! have_mpi && [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
    echo "test.sh: installing OpenMPI and libclang for the MPI tests…"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends openmpi-bin libopenmpi-dev \
        libclang-dev >/dev/null
fi
MPI_SKIPPED=
if have_mpi; then
    cargo test --release --features mpi --test mpi_reconstruct --test mpi_render \
        --test distributed_reconstruct --test distributed_render
elif [ "${VOXLAB_ALLOW_NO_MPI:-}" = "1" ]; then
    MPI_SKIPPED=1
else
    echo "test.sh: no MPI (mpirun, mpicc) or libclang, and cannot install them (needs root"
    echo "test.sh: and apt-get): install openmpi-bin libopenmpi-dev libclang-dev, or set"
    echo "test.sh: VOXLAB_ALLOW_NO_MPI=1 to skip the MPI tests."
    exit 1
fi

if [ -n "$MPI_SKIPPED" ]; then
    echo
    echo "************************************************************"
    echo "*  MPI TESTS SKIPPED (no MPI, VOXLAB_ALLOW_NO_MPI=1):       *"
    echo "*    tests/mpi_reconstruct.rs, tests/mpi_render.rs         *"
    echo "************************************************************"
fi

if [ -s target/gpu-tests-skipped.txt ]; then
    echo
    echo "************************************************************"
    echo "*  GPU TESTS SKIPPED (no adapter, VOXLAB_ALLOW_NO_GPU=1):  *"
    sed 's/^/*    /' target/gpu-tests-skipped.txt
    echo "************************************************************"
fi
