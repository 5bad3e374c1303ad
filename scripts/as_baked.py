#!/usr/bin/env python3
"""Renders a light bake's KTX2 texture as emission and absorption: the reference image for the
Bevy viewer's baked-fog material (scripts/engine-check.sh).

    as_baked.py BAKE.ktx2 PROJECT.ron OUT.exr [--width W --height H]

What `shaders/as_baked.wgsl` computes, on the CPU from the exported file: the project's camera
(pixel-centre rays, vertical field of view), the grid box from the texture's
`fogsmith.grid_min` / `fogsmith.grid_max`, emission (RGB) and extinction (A) times
`fogsmith.emission_scale` / `fogsmith.extinction_scale`, trilinear between cell centres and
clamped at the faces, uniform steps of 1/8 of the smallest cell edge integrated exactly
(L += T j (1 - e^(-s d)) / s, T *= e^(-s d)). Writes the linear radiance as an RGB EXR.
`fogsmith render` has no option to render the bake itself (the editor's "as baked" preview
modes do), so the check renders the exported file with this.

Needs numpy and OpenEXR's Python bindings (the project's .venv from ./setup.sh).
"""

import argparse
import re
import struct
import sys

import numpy as np
import OpenEXR

STEPS_PER_CELL = 8.0
CUTOFF = 1e-6
VK_FORMAT_R16G16B16A16_SFLOAT = 97


def read_bake(path):
    """(grid_min, grid_max, texels (z, y, x, 4) float32 with the scales applied)."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:12] != b"\xabKTX 20\xbb\r\n\x1a\n":
        sys.exit(f"{path}: not a KTX2 file; pass the texture `fogsmith export --bake-light --ktx2` wrote")
    fmt, _, w, h, d, layers, faces, levels, scheme = struct.unpack_from("<9I", data, 12)
    if fmt != VK_FORMAT_R16G16B16A16_SFLOAT or scheme != 0 or d < 1:
        sys.exit(f"{path}: not a light bake (an uncompressed RGBA16F 3D texture); export it with --bake-light --ktx2")
    kvd_offset, kvd_length = struct.unpack_from("<II", data, 56)
    level_offset, level_length = struct.unpack_from("<QQ", data, 80)
    kv, at, end = {}, kvd_offset, kvd_offset + kvd_length
    while at + 4 <= end:
        (n,) = struct.unpack_from("<I", data, at)
        key, _, value = data[at + 4 : at + 4 + n].partition(b"\0")
        kv[key.decode()] = value.rstrip(b"\0").decode()
        at += 4 + (n + 3) // 4 * 4
    try:
        lo = np.array([float(v) for v in kv["fogsmith.grid_min"].split()])
        hi = np.array([float(v) for v in kv["fogsmith.grid_max"].split()])
        e_scale = float(kv.get("fogsmith.emission_scale", "1"))
        a_scale = float(kv.get("fogsmith.extinction_scale", "1"))
    except (KeyError, ValueError) as e:
        sys.exit(f"{path}: missing or bad Fogsmith key/value data ({e}); export it again")
    texels = np.frombuffer(data, dtype="<f2", count=w * h * d * 4, offset=level_offset).astype(np.float32)
    texels = texels.reshape(d, h, w, 4) * np.array([e_scale, e_scale, e_scale, a_scale], dtype=np.float32)
    return lo, hi, texels


def ron_group(text, key):
    """The text inside the parentheses after `key:` (balanced), or None."""
    m = re.search(r"\b" + key + r"\s*:\s*\(", text)
    if not m:
        return None
    depth, start = 1, m.end()
    for i in range(start, len(text)):
        depth += {"(": 1, ")": -1}.get(text[i], 0)
        if depth == 0:
            return text[start:i]
    return None


def read_camera(path):
    """position, target, up, fov_y_deg and the render size of a Fogsmith project."""
    text = re.sub(r"//[^\n]*", "", open(path).read())
    cam = ron_group(text, "camera")
    if cam is None:
        sys.exit(f"{path}: no camera; pass the project the bake was exported from")

    def vec(key, default):
        group = ron_group(cam, key)
        if group is None:
            if default is None:
                sys.exit(f"{path}: the camera has no {key}")
            return np.array(default, dtype=np.float64)
        return np.array([float(v) for v in group.split(",")], dtype=np.float64)

    fov = re.search(r"fov_y_deg\s*:\s*([-\d.eE+]+)", cam)
    render = ron_group(text, "render") or ""
    size = [re.search(k + r"\s*:\s*(\d+)", render) for k in ("width", "height")]
    return (
        vec("position", None),
        vec("target", None),
        vec("up", [0.0, 1.0, 0.0]),
        float(fov.group(1)) if fov else 40.0,
        [int(s.group(1)) if s else d for s, d in zip(size, (640, 360))],
    )


def render(lo, hi, texels, position, target, up, fov, width, height):
    forward = (target - position) / np.linalg.norm(target - position)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    tan_half = np.tan(np.radians(fov) * 0.5)
    sx = ((np.arange(width) + 0.5) / width * 2.0 - 1.0) * tan_half * width / height
    sy = (1.0 - (np.arange(height) + 0.5) / height * 2.0) * tan_half
    dirs = forward + right * sx[None, :, None] + up * sy[:, None, None]
    dirs = (dirs / np.linalg.norm(dirs, axis=-1, keepdims=True)).reshape(-1, 3)
    safe = np.where(np.abs(dirs) < 1e-30, 1e-30, dirs)
    a, b = (lo - position) / safe, (hi - position) / safe
    t0 = np.maximum(np.minimum(a, b).max(axis=1), 0.0)
    t1 = np.maximum(a, b).min(axis=1)
    dims = np.array(texels.shape[2::-1])
    cell = (hi - lo) / dims
    step = cell.min() / STEPS_PER_CELL
    out = np.zeros((width * height, 3))
    live = np.nonzero(t1 > t0)[0]
    n = np.maximum(np.ceil((t1[live] - t0[live]) / step), 1.0)
    dt = (t1[live] - t0[live]) / n
    radiance = np.zeros((live.size, 3))
    tr = np.ones(live.size)
    flat = texels.reshape(-1, 4)
    for k in range(int(n.max()) if live.size else 0):
        on = (k < n) & (tr >= CUTOFF)
        if not on.any():
            break
        idx = np.nonzero(on)[0]
        p = position + dirs[live[idx]] * (t0[live[idx]] + (k + 0.5) * dt[idx])[:, None]
        u = np.clip((p - lo) / cell - 0.5, 0.0, dims - 1)
        i0 = np.floor(u).astype(np.int64)
        i1 = np.minimum(i0 + 1, dims - 1)
        f = u - i0
        s = np.zeros((idx.size, 4))
        for c in range(8):
            pick = [(c >> axis) & 1 for axis in range(3)]
            ii = [np.where(pick[axis], i1[:, axis], i0[:, axis]) for axis in range(3)]
            w = np.prod([np.where(pick[axis], f[:, axis], 1.0 - f[:, axis]) for axis in range(3)], axis=0)
            s += w[:, None] * flat[ii[0] + dims[0] * (ii[1] + dims[1] * ii[2])]
        sigma, tau = s[:, 3], s[:, 3] * dt[idx]
        safe_sigma = np.where(tau < 1e-6, 1.0, sigma)
        weight = np.where(tau < 1e-6, dt[idx] * (1.0 - 0.5 * tau), -np.expm1(-tau) / safe_sigma)
        radiance[idx] += (tr[idx] * weight)[:, None] * s[:, :3]
        tr[idx] *= np.exp(-tau)
    out[live] = radiance
    return out.reshape(height, width, 3)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bake")
    ap.add_argument("project")
    ap.add_argument("out")
    ap.add_argument("--width", type=int)
    ap.add_argument("--height", type=int)
    args = ap.parse_args()
    lo, hi, texels = read_bake(args.bake)
    position, target, up, fov, (width, height) = read_camera(args.project)
    width, height = args.width or width, args.height or height
    img = render(lo, hi, texels, position, target, up, fov, width, height).astype(np.float32)
    channels = {c: img[:, :, i].copy() for i, c in enumerate("RGB")}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, channels) as f:
        f.write(args.out)


if __name__ == "__main__":
    main()
