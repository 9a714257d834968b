"""Filtered backprojection: voxlab.transform.iradon against scikit-image's iradon on
the same sinogram (voxlab.transform.radon of the Shepp–Logan phantom, equal to
scikit-image's radon), and their difference."""

import numpy as np
from skimage.data import shepp_logan_phantom
from skimage.transform import iradon, rescale

import voxlab.transform as vt
from _common import out_path, plt, save

path = out_path("fbp_vs_iradon.png")
img = rescale(shepp_logan_phantom(), 0.25, mode="reflect", channel_axis=None)  # 100²
theta = np.linspace(0, 180, 120, endpoint=False)
sino = vt.radon(img, theta)
ours = vt.iradon(sino, theta, filter_name="ramp")
peer = iradon(sino, theta, filter_name="ramp")
d = ours - peer
fig, axes = plt.subplots(1, 4, figsize=(13, 3.4))
for ax, a, t in zip(axes, [sino, ours, peer], ["sinogram (voxlab radon)", "voxlab iradon",
                                              "skimage iradon"]):
    ax.imshow(a, cmap="gray", aspect="auto" if a is sino else "equal"); ax.set_title(t)
    ax.set_axis_off()
m = axes[3].imshow(d, cmap="RdBu", vmin=-np.abs(d).max(), vmax=np.abs(d).max())
axes[3].set_title(f"difference (max {np.abs(d).max():.1e})"); axes[3].set_axis_off()
fig.colorbar(m, ax=axes[3], fraction=0.046)
save(fig, path)
