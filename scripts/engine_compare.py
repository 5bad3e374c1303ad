#!/usr/bin/env python3
"""Compares a Bevy viewer screenshot with Fogsmith's linear render of the same view.

The viewer's PNG holds exposure x linear radiance, sRGB-encoded with no tone curve
(engines/bevy); Fogsmith's EXR (`fogsmith render -o X.exr`) holds linear radiance. Both are
brought to linear radiance before comparing. Two checks, as in scripts/engine-check.sh:

    engine_compare.py bake   BEVY.png FOGSMITH.exr EXPOSURE [--label TEXT]   # mean, robust rel-RMSE
                                         # (with a label: printed for information, no bound)
    engine_compare.py shape  BEVY.png FOGSMITH.exr            # IoU of the lit silhouettes
    engine_compare.py opacity BEVY.png BACKGROUND FOGSMITH.exr  # IoU of the opacity silhouettes
    engine_compare.py peak   IMAGE.png|IMAGE.exr              # the largest linear value

`bake`: the mean radiance (all pixels, all channels) must agree within 3 %, and the robust
relative RMSE, over 4x4-pixel blocks of the channel mean divided by Fogsmith's mean (the
measure tests/blender_bake.rs uses; blocks keep the fog's shape and forgive one-pixel edge
differences), must be at most 5 %. `shape`: each image's silhouette is the pixels whose
luminance is above 5 % of that image's maximum; their intersection over union must be at
least 0.9. `opacity`: the same IoU, of the pixels whose opacity is above 5 %: Bevy's
opacity is 1 - image / BACKGROUND for a shot of the fog in front of a grey BACKGROUND with
its own light exposed away (the viewer's --background), Fogsmith's is its EXR's alpha
(1 - transmittance). Prints one line per figure and exits 1 when a bound is missed.

Needs numpy and OpenEXR's Python bindings (the project's .venv from ./setup.sh).
"""

import os
import sys

import numpy as np
import OpenEXR

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from png_strip import read_png  # noqa: E402

MEAN_BOUND = 0.03
RMSE_BOUND = 0.05
IOU_BOUND = 0.9
SILHOUETTE = 0.05
BLOCK = 4


def linear_png(path):
    """The PNG as linear RGB in 0..1 (sRGB decoded), shape (h, w, 3)."""
    width, height, rows = read_png(path)
    v = np.frombuffer(b"".join(rows), dtype=np.uint8).reshape(height, width, 3) / 255.0
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def linear_exr(path):
    """The EXR's R, G, B as float64, shape (h, w, 3)."""
    with OpenEXR.File(path, separate_channels=True) as f:
        ch = f.channels()
        missing = [c for c in "RGB" if c not in ch]
        if missing:
            sys.exit(f"{path}: no channel {', '.join(missing)}; pass `fogsmith render`'s EXR")
        return np.stack([ch[c].pixels.astype(np.float64) for c in "RGB"], axis=-1)


def blocks(img):
    h, w = img.shape[0] // BLOCK * BLOCK, img.shape[1] // BLOCK * BLOCK
    return img[:h, :w].reshape(h // BLOCK, BLOCK, w // BLOCK, BLOCK).mean(axis=(1, 3))


def same_size(bevy, fog, bevy_path, fog_path):
    if bevy.shape != fog.shape:
        sys.exit(
            f"{bevy_path} is {bevy.shape[1]}x{bevy.shape[0]} but {fog_path} is "
            f"{fog.shape[1]}x{fog.shape[0]}; render both at one size"
        )


def compare_bake(bevy_path, fog_path, exposure, label="bake"):
    fog = linear_exr(fog_path)
    bevy = linear_png(bevy_path) / exposure
    same_size(bevy, fog, bevy_path, fog_path)
    clipped = np.mean(bevy.max(axis=-1) * exposure >= 254.5 / 255.0)
    mf, mb = fog.mean(), bevy.mean()
    if mf <= 0:
        sys.exit(f"{fog_path}: the render is black")
    mean_diff = mb / mf - 1.0
    pixel_rmse = np.sqrt(np.mean((bevy - fog) ** 2)) / mf
    bf, bb = blocks(fog.mean(axis=-1)), blocks(bevy.mean(axis=-1))
    robust = np.sqrt(np.mean((bb - bf) ** 2)) / mf
    gated = label == "bake"
    mean_bound = f" (bound ±{100 * MEAN_BOUND:.0f} %)" if gated else ""
    rmse_bound = f" (bound {100 * RMSE_BOUND:.0f} %)" if gated else ""
    print(f"{label}: mean Bevy {mb:.5g}, Fogsmith {mf:.5g}: difference {100 * mean_diff:+.2f} %{mean_bound}")
    print(f"{label}: robust rel-RMSE (4x4 blocks) {100 * robust:.2f} %{rmse_bound}; per pixel {100 * pixel_rmse:.2f} %")
    if clipped > 0:
        print(f"{label}: warning: {100 * clipped:.2f} % of Bevy's pixels are at 255 (clipped); lower the exposure")
    return not gated or (abs(mean_diff) <= MEAN_BOUND and robust <= RMSE_BOUND)


def compare_shape(bevy_path, fog_path):
    fog = linear_exr(fog_path).mean(axis=-1)
    bevy = linear_png(bevy_path).mean(axis=-1)
    same_size(bevy, fog, bevy_path, fog_path)
    if fog.max() <= 0 or bevy.max() <= 0:
        sys.exit(f"{'Bevy' if bevy.max() <= 0 else 'Fogsmith'}'s image is black: no silhouette to compare")
    a, b = bevy > SILHOUETTE * bevy.max(), fog > SILHOUETTE * fog.max()
    iou = np.sum(a & b) / np.sum(a | b)
    print(
        f"shape: IoU of the silhouettes (> {100 * SILHOUETTE:.0f} % of max) {iou:.4f} (bound {IOU_BOUND}); "
        f"Bevy {int(a.sum())} px, Fogsmith {int(b.sum())} px, both {int((a & b).sum())}"
    )
    return iou >= IOU_BOUND


def compare_opacity(bevy_path, background, fog_path):
    with OpenEXR.File(fog_path, separate_channels=True) as f:
        ch = f.channels()
        if "A" not in ch:
            sys.exit(f"{fog_path}: no alpha channel; pass `fogsmith render`'s EXR")
        fog = ch["A"].pixels.astype(np.float64)
    bevy = 1.0 - linear_png(bevy_path).mean(axis=-1) / background
    same_size(bevy, fog, bevy_path, fog_path)
    a, b = bevy > SILHOUETTE, fog > SILHOUETTE
    iou = np.sum(a & b) / np.sum(a | b)
    print(
        f"opacity: IoU of the silhouettes (opacity > {100 * SILHOUETTE:.0f} %) {iou:.4f} (bound {IOU_BOUND}); "
        f"Bevy {int(a.sum())} px, Fogsmith {int(b.sum())} px, both {int((a & b).sum())}"
    )
    return iou >= IOU_BOUND


def peak(path):
    img = linear_exr(path) if path.lower().endswith(".exr") else linear_png(path)
    print(float(img.max()))
    return True


def main(argv):
    label = "bake"
    if len(argv) == 7 and argv[5] == "--label":
        label, argv = argv[6], argv[:5]
    if len(argv) == 5 and argv[1] == "bake":
        ok = compare_bake(argv[2], argv[3], float(argv[4]), label)
    elif len(argv) == 4 and argv[1] == "shape":
        ok = compare_shape(argv[2], argv[3])
    elif len(argv) == 5 and argv[1] == "opacity":
        ok = compare_opacity(argv[2], float(argv[3]), argv[4])
    elif len(argv) == 3 and argv[1] == "peak":
        ok = peak(argv[2])
    else:
        sys.exit(__doc__)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv))
