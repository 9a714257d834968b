"""DVR of the modified Shepp–Logan head with a transfer function built from control
points, beside the transfer function itself."""

import numpy as np

import voxlab
from _common import out_path, plt, save

path = out_path("dvr_transfer_function.png")
tf = voxlab.TransferFunction.from_points([
    (0.00, (0.0, 0.0, 0.0, 0.0)),
    (0.15, (0.9, 0.6, 0.4, 0.02)),
    (0.30, (1.0, 0.9, 0.7, 0.25)),
    (1.00, (1.0, 1.0, 1.0, 0.9)),
])
img = voxlab.render("phantom:shepp-logan-modified:64", tf=tf, width=160, height=160,
                    azimuth=30, elevation=20, backend="cpu-f32").image
x = np.linspace(0, 1, 256)
rgba = tf(x)
fig, (a, b) = plt.subplots(1, 2, figsize=(8, 3.6), gridspec_kw={"width_ratios": [1.3, 1]})
for k, c in enumerate("rgb"):
    a.plot(x, rgba[:, k], color=c, lw=1)
a.plot(x, rgba[:, 3], color="k", lw=2, label="opacity")
a.set_xlabel("value"); a.set_title("transfer function"); a.legend(loc="upper left")
b.imshow(np.clip(img, 0, 1)); b.set_axis_off(); b.set_title("DVR (cpu-f32)")
save(fig, path)
