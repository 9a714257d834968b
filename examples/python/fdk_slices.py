"""FDK: a cone-beam scan of the Shepp–Logan phantom (exact line integrals, RTK's
geometry) reconstructed on a 64³ grid; the three central slices."""

import voxlab.ct as vct
from _common import out_path, plt, save

path = out_path("fdk_slices.png")
p = vct.project("phantom:shepp-logan-modified", beam="cone", angles=90, cols=64, rows=64)
rec = vct.reconstruct(p.projections, p.geometry, size=64).array  # (z, y, x)
n = rec.shape[0] // 2
fig, axes = plt.subplots(1, 4, figsize=(13, 3.4))
axes[0].imshow(p.projections[0], cmap="gray"); axes[0].set_title("projection 0")
for ax, s, t in zip(axes[1:], [rec[n], rec[:, n], rec[:, :, n]], ["z = 32", "y = 32", "x = 32"]):
    ax.imshow(s, cmap="gray", vmin=0, vmax=0.4); ax.set_title(f"FDK, {t}")
for ax in axes:
    ax.set_axis_off()
save(fig, path)
