"""What every gallery script shares: a headless matplotlib and the output folder
(``--out DIR``, default the current folder)."""

import argparse
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def out_path(name: str) -> str:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--out", default=".", help="folder for the figure")
    a = p.parse_args()
    os.makedirs(a.out, exist_ok=True)
    return os.path.join(a.out, name)


def save(fig, path: str) -> None:
    fig.savefig(path, dpi=80, bbox_inches="tight")
    plt.close(fig)
    print(path)
