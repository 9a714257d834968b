"""The reconstruction filters on the Marschner–Lobb test signal (41³): nearest,
trilinear, Catmull–Rom and Lanczos-3, the same DVR scene (the phantom's default
transfer function) with each filter."""

import numpy as np

import voxlab
from _common import out_path, plt, save

path = out_path("filters_marschner_lobb.png")
filters = ["nearest", "trilinear", "catmull-rom", "lanczos3"]
fig, axes = plt.subplots(1, 4, figsize=(12, 3.3))
for ax, f in zip(axes, filters):
    img = voxlab.render("phantom:marschner-lobb:41", filter=f, width=120, height=120,
                        elevation=30, backend="cpu-f32").image
    ax.imshow(np.clip(img, 0, 1)); ax.set_axis_off(); ax.set_title(f)
save(fig, path)
