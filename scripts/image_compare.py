#!/usr/bin/env python3
"""Compares two linear EXR images of the same size: a render against a reference.

    .venv/bin/python scripts/image_compare.py RENDER.exr REFERENCE.exr [--json]

Reports the ratio of the image means, the relative RMSE of physics.md §8
(sqrt(mean((L − L_ref)²)) / mean(L_ref)), and two robust variants for Monte Carlo references,
whose noise dominates the plain RMSE near a light inside the fog:
- `rel_rmse_99`: the same over the pixels without the 1 % largest per-pixel differences;
- `rel_rmse_box3`: the same after a 3×3 box filter of both images;
- `rel_rmse_box3_99`: both: the filtered images without the 1 % largest differences (the noise
  of a light inside the fog spreads over the filter's pixels, which the filter alone keeps).
"""

import argparse
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from engine_compare import linear_exr  # noqa: E402


def box3(x):
    p = np.pad(x, ((1, 1), (1, 1), (0, 0)), mode="edge")
    return sum(p[i:i + x.shape[0], j:j + x.shape[1]] for i in range(3) for j in range(3)) / 9.0


def compare(a, b):
    if a.shape != b.shape:
        raise SystemExit(f"image_compare: the images differ in size: {a.shape} and {b.shape}")
    mean = b.mean()
    if not mean > 0:
        raise SystemExit("image_compare: the reference is black (mean ≤ 0); nothing to compare against")
    sq = ((a - b) ** 2).mean(axis=2)
    keep = sq <= np.quantile(sq, 0.99)
    sq3 = ((box3(a) - box3(b)) ** 2).mean(axis=2)
    keep3 = sq3 <= np.quantile(sq3, 0.99)
    return {
        "mean": float(a.mean()),
        "reference_mean": float(mean),
        "mean_ratio": float(a.mean() / mean),
        "rel_rmse": float(np.sqrt(sq.mean()) / mean),
        "rel_rmse_99": float(np.sqrt(sq[keep].mean()) / mean),
        "rel_rmse_box3": float(np.sqrt(sq3.mean()) / mean),
        "rel_rmse_box3_99": float(np.sqrt(sq3[keep3].mean()) / mean),
        "nan": int(np.isnan(a).sum()),
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("render")
    ap.add_argument("reference")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    r = compare(linear_exr(args.render), linear_exr(args.reference))
    if args.json:
        print(json.dumps(r))
    else:
        print("mean ratio {mean_ratio:.4f}, rel-RMSE {rel_rmse:.4f}, without the 1 % largest differences "
              "{rel_rmse_99:.4f}, 3×3-filtered {rel_rmse_box3:.4f}, both {rel_rmse_box3_99:.4f}".format(**r))


if __name__ == "__main__":
    main()
