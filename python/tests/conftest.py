"""Shared fixtures: the repository, the command line (for CLI-vs-Python checks) and the
GPU policy of the Rust tests (no adapter fails, unless VOXLAB_ALLOW_NO_GPU=1, which
skips loudly and records the skip in target/gpu-tests-skipped.txt)."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

import voxlab

REPO = Path(__file__).resolve().parents[2]


def target_dir() -> Path:
    t = os.environ.get("CARGO_TARGET_DIR")
    return Path(t) if t else REPO / "target"


@pytest.fixture(scope="session")
def repo() -> Path:
    return REPO


@pytest.fixture(scope="session")
def cli():
    """Runs the `voxlab` binary of this checkout (built by `cargo test --release`,
    which scripts/test.sh runs first; VOXLAB_BIN overrides)."""
    exe = Path(os.environ.get("VOXLAB_BIN", target_dir() / "release" / "voxlab"))
    if not exe.is_file():
        pytest.fail(
            f"no voxlab binary at {exe}: build it with `cargo build --release` "
            "(scripts/test.sh does) or set VOXLAB_BIN"
        )

    def run(*args, check=True):
        r = subprocess.run(
            [str(exe), *map(str, args)], cwd=REPO, capture_output=True, text=True
        )
        if check and r.returncode != 0:
            raise AssertionError(f"voxlab {' '.join(map(str, args))} failed:\n{r.stderr}")
        return r

    return run


_gpu_state = {}


@pytest.fixture
def gpu(request):
    """A GPU renderer, or: a failure without an adapter, unless VOXLAB_ALLOW_NO_GPU=1,
    which skips the test loudly."""
    if "renderer" not in _gpu_state:
        try:
            _gpu_state["renderer"] = voxlab.Renderer("gpu")
        except voxlab.NoGpuError as e:
            _gpu_state["renderer"] = e
    r = _gpu_state["renderer"]
    if isinstance(r, Exception):
        name = f"python/{request.node.nodeid}"
        if os.environ.get("VOXLAB_ALLOW_NO_GPU") == "1":
            msg = (f"\n*** GPU TEST SKIPPED: {name}: {r}\n"
                   "*** (VOXLAB_ALLOW_NO_GPU=1 allows this; the GPU code was NOT tested)\n")
            sys.__stderr__.write(msg)
            t = target_dir()
            t.mkdir(parents=True, exist_ok=True)
            with open(t / "gpu-tests-skipped.txt", "a") as fh:
                fh.write(name + "\n")
            pytest.skip(f"no GPU adapter: {r}")
        pytest.fail(
            f"no GPU adapter for {name}: {r}\nInstall a Vulkan driver (the README's test "
            "command does this when run as root), or set VOXLAB_ALLOW_NO_GPU=1 to skip "
            "the GPU tests."
        )
    return r
