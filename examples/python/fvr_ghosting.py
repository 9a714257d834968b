"""Fourier volume rendering of a sphere pair: without zero padding the inverse FFT of
the spectrum's slice wraps around (ghosts at the image edges); padding ×2 removes
them (trilinear kernel, voxlab.fvr)."""

import numpy as np

import voxlab
from _common import out_path, plt, save

path = out_path("fvr_ghosting.png")
vol = "phantom:spheres:48"
a = voxlab.fvr(vol, kernel="trilinear", padding=1, azimuth=35, elevation=20)
b = voxlab.fvr(vol, kernel="trilinear", padding=2, azimuth=35, elevation=20)
fig, axes = plt.subplots(1, 3, figsize=(10, 3.6))
v = max(a.max(), b.max())
for ax, img, t in zip(axes, [a, b, a - b], ["padding 1 (ghosts)", "padding 2",
                                            "difference"]):
    ax.imshow(img, cmap="gray" if t != "difference" else "RdBu",
              vmin=-v / 4 if t == "difference" else 0, vmax=v / 4 if t == "difference" else v)
    ax.set_title(t); ax.set_axis_off()
save(fig, path)
