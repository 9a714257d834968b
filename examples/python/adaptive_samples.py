"""Samples per ray of regular, direct and spectral adaptive sampling of the
Marschner–Lobb signal (voxlab.adaptive), with each image's error from the report."""

import voxlab
from _common import out_path, plt, save

path = out_path("adaptive_samples.png")
r = voxlab.adaptive("phantom:marschner-lobb:32", size=96, runs=1)
rows = r.report["rows"]
fig, axes = plt.subplots(2, len(rows), figsize=(3.2 * len(rows), 6.2))
for k, row in enumerate(rows):
    name = row["sampling"]
    axes[0, k].imshow(r.images[name][..., :3].clip(0, 1))
    axes[0, k].set_title(f"{name}: PSNR {row['psnr_db']:.1f} dB" if row["max_abs"] else name)
    m = axes[1, k].imshow(r.samples[name], cmap="magma", vmin=0, vmax=r.max_count)
    axes[1, k].set_title(f"{row['samples_per_pixel']:.1f} samples / pixel")
for ax in axes.flat:
    ax.set_axis_off()
fig.colorbar(m, ax=axes[1, :].tolist(), fraction=0.02)
save(fig, path)
