#!/usr/bin/env python3
"""Renders a Fogsmith project with Mitsuba 3's volumetric path tracer, as an outside reference.

    .venv/bin/python scripts/mitsuba_reference.py PROJECT.ron OUT.exr [--max-depth -1]
        [--spp 256] [--passes 4] [--width 96] [--json]

`--max-depth 2` is single scattering in Mitsuba 3 (what Fogsmith computes today); `-1` is
every order. The image is linear radiance, the layout of `fogsmith render -o X.exr`, so that
`scripts/image_compare.py` can diff the two.

The scene is rebuilt from the project file alone, not from Fogsmith's grids, so the reference
shares no code or data with the renderer it checks:
- The extinction is the exact gaussian sum (physics.md §2) evaluated at the centres of a grid
  `--oversample` times finer than the project's (default 2) inside the project's grid box,
  trilinearly filtered by Mitsuba, and zero outside the box. Fogsmith's particle culling
  (influence below 1e-6 of the peak) is not applied.
- Point lights are Mitsuba `point` lights of intensity `intensity·color` (W/sr), suns are
  `directional` lights of irradiance `intensity·color`, spot lights are `spot` lights with
  `cutoff_angle` = the spot's angle and `beam_width` = angle·(1 − blend). Mitsuba's falloff
  between the two is linear in angle, Fogsmith's a smoothstep (physics.md §9): they agree
  inside the inner cone and outside the outer one only.
- The camera is a pinhole with the project's vertical field of view.

What the reference cannot represent is refused with an error naming the field: base fog,
height fog, noise, surfaces, an imported base volume, a camera inside the grid box.

`--passes N` renders N independent images (different seeds) of `--spp` samples each; the
output is their mean, and the JSON summary gives the standard error of the image mean from
the spread of the passes.
"""

import argparse
import json
import math
import re
import sys
import time

import numpy as np


class Ron:
    """A small reader for the RON that Fogsmith writes: structs `(a: 1)` and `Name(a: 1)`,
    tuples `(1, 2)`, lists, strings, numbers, booleans, `Some(x)`, `None` and unit enums."""

    TOKEN = re.compile(r'\s+|//[^\n]*|/\*.*?\*/|"(?:[^"\\]|\\.)*"|[-+]?(?:\d+\.?\d*(?:[eE][-+]?\d+)?|inf|NaN)'
                       r'|[A-Za-z_][A-Za-z0-9_]*|[()\[\]{}:,]', re.S)

    def __init__(self, text):
        self.tokens = []
        pos = 0
        while pos < len(text):
            m = self.TOKEN.match(text, pos)
            if not m:
                raise ValueError(f"RON: cannot read {text[pos:pos + 20]!r}")
            tok = m.group(0)
            pos = m.end()
            if tok.strip() and not tok.startswith("//") and not tok.startswith("/*"):
                self.tokens.append(tok)
        self.i = 0

    def peek(self, k=0):
        return self.tokens[self.i + k] if self.i + k < len(self.tokens) else None

    def take(self, expected=None):
        tok = self.peek()
        if expected is not None and tok != expected:
            raise ValueError(f"RON: expected {expected!r}, found {tok!r}")
        self.i += 1
        return tok

    def value(self):
        tok = self.peek()
        if tok == "(":
            return self.group()
        if tok == "[":
            self.take("[")
            return self.items("]")
        if tok.startswith('"'):
            self.take()
            return json.loads(tok)
        if tok in ("true", "false"):
            self.take()
            return tok == "true"
        if tok == "None":
            self.take()
            return None
        if re.match(r"[-+]?(\d|inf|NaN)", tok):
            self.take()
            return float(tok)
        # An identifier: Some(x), a named struct or enum variant, or a unit variant.
        self.take()
        if self.peek() == "(":
            inner = self.group()
            if tok == "Some":
                return inner[0] if isinstance(inner, list) and len(inner) == 1 else inner
            if tok == "Project":
                return inner
            return {"__variant": tok, **(inner if isinstance(inner, dict) else {"values": inner})}
        return {"__variant": tok}

    def group(self):
        self.take("(")
        if self.peek() == ")":
            self.take(")")
            return []
        if self.peek(1) == ":":
            fields = {}
            while self.peek() != ")":
                name = self.take()
                self.take(":")
                fields[name] = self.value()
                if self.peek() == ",":
                    self.take(",")
            self.take(")")
            return fields
        return self.items(")")

    def items(self, close):
        """Comma-separated values up to and including `close`."""
        items = []
        while self.peek() != close:
            items.append(self.value())
            if self.peek() == ",":
                self.take(",")
        self.take(close)
        return items


def refuse(field, why):
    sys.exit(f"mitsuba_reference: {field}: {why}; the reference renders gaussian particles in the grid box only")


def load_project(path):
    p = Ron(open(path).read()).value()
    m = p.get("medium", {})
    if m.get("base_extinction", 0.0) != 0.0:
        refuse("medium.base_extinction", "base fog fills all space, which this reference does not model")
    if m.get("noise") is not None:
        refuse("medium.noise", "noise is not modelled")
    s = p.get("surfaces") or {}
    if s.get("ground") is not None or s.get("boxes"):
        refuse("surfaces", "surfaces are not modelled")
    if p.get("base_volume") is not None:
        refuse("base_volume", "an imported volume is not modelled")
    return p


def extinction_grid(p, oversample):
    g = p["grid"]
    lo = np.array(g["min"], float)
    hi = np.array(g["max"], float)
    n = np.array(g["resolution"], int) * oversample
    axes = [lo[a] + (np.arange(n[a]) + 0.5) * (hi[a] - lo[a]) / n[a] for a in range(3)]
    z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    sigma = np.zeros(x.shape)
    for q in p.get("particles", []):
        if q.get("hidden", False):
            continue
        c = q["center"]
        r = q["radius"]
        d2 = (x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2
        sigma += q["density"] * np.exp(-d2 / (r * r))
    return lo, hi, sigma.astype(np.float32)


def normalize(v):
    v = np.array(v, float)
    return v / np.linalg.norm(v)


def scene_dict(p, mi, width, height, spp, max_depth, oversample):
    lo, hi, sigma = extinction_grid(p, oversample)
    cam = p["camera"]
    eye = np.array(cam["position"], float)
    if np.all(eye > lo) and np.all(eye < hi):
        refuse("camera.position", "the camera is inside the grid box")
    T = mi.ScalarTransform4f
    m = p["medium"]
    centre = 0.5 * (lo + hi)
    half = 0.5 * (hi - lo)
    medium = {
        "type": "heterogeneous",
        "albedo": float(m.get("albedo", 1.0)),
        "sigma_t": {
            "type": "gridvolume",
            "grid": mi.VolumeGrid(sigma[..., None]),
            "filter_type": "trilinear",
            "to_world": T().translate(lo.tolist()).scale((hi - lo).tolist()),
        },
        "scale": 1.0,
        "phase": {"type": "hg", "g": float(m.get("anisotropy", 0.0))},
    }
    scene = {
        "type": "scene",
        "integrator": {"type": "volpath", "max_depth": int(max_depth), "rr_depth": 1000},
        "sensor": {
            "type": "perspective",
            "fov_axis": "y",
            "fov": float(cam["fov_y_deg"]),
            "to_world": T().look_at(origin=eye.tolist(), target=list(cam["target"]), up=list(cam["up"])),
            "film": {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"},
                     "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": spp},
        },
        "fog": {
            "type": "cube",
            "to_world": T().translate(centre.tolist()).scale(half.tolist()),
            "bsdf": {"type": "null"},
            "interior": medium,
        },
    }
    for k, light in enumerate(p.get("lights", [])):
        if light.get("hidden", False):
            continue
        rgb = (np.array(light.get("color", [1, 1, 1]), float) * light["intensity"]).tolist()
        kind = light.get("kind", {"__variant": "Point"})
        variant = kind["__variant"] if isinstance(kind, dict) else kind
        pos = list(light["position"])
        if variant == "Point":
            scene[f"light{k}"] = {"type": "point", "position": pos,
                                  "intensity": {"type": "rgb", "value": rgb}}
        elif variant == "Directional":
            d = normalize(kind["direction"])
            scene[f"light{k}"] = {"type": "directional", "direction": d.tolist(),
                                  "irradiance": {"type": "rgb", "value": rgb}}
        elif variant == "Spot":
            d = normalize(kind["direction"])
            angle = float(kind["angle_deg"])
            blend = float(kind.get("blend", 0.0))
            scene[f"light{k}"] = {
                "type": "spot",
                "to_world": T().look_at(origin=pos, target=(np.array(pos) + d).tolist(),
                                        up=[0, 1, 0] if abs(d[1]) < 0.99 else [1, 0, 0]),
                "intensity": {"type": "rgb", "value": rgb},
                "cutoff_angle": angle,
                "beam_width": max(angle * (1.0 - blend), 1e-3),
            }
        else:
            refuse(f"lights[{k}].kind", f"unknown light kind {variant}")
    return scene


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("project")
    ap.add_argument("output", help="linear EXR")
    ap.add_argument("--max-depth", type=int, default=-1, help="2: single scattering; -1: all orders")
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--passes", type=int, default=4)
    ap.add_argument("--width", type=int, default=0, help="default: the project's render width")
    ap.add_argument("--oversample", type=int, default=2)
    ap.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    args = ap.parse_args()

    import mitsuba as mi
    mi.set_variant("llvm_ad_rgb")
    p = load_project(args.project)
    r = p.get("render", {})
    w0, h0 = int(r.get("width", 320)), int(r.get("height", 180))
    width = args.width or w0
    height = max(1, round(width * h0 / w0))
    scene = mi.load_dict(scene_dict(p, mi, width, height, args.spp, args.max_depth, args.oversample))
    started = time.time()
    images = []
    for k in range(args.passes):
        images.append(np.array(mi.render(scene, seed=1000 + k), dtype=np.float64))
    seconds = time.time() - started
    stack = np.stack(images)
    image = stack.mean(axis=0)
    mi.Bitmap(image.astype(np.float32), pixel_format=mi.Bitmap.PixelFormat.RGB).write(args.output)
    means = stack.reshape(args.passes, -1, 3).mean(axis=1)
    lum = means.mean(axis=1)
    stderr = float(lum.std(ddof=1) / math.sqrt(args.passes)) if args.passes > 1 else float("nan")
    summary = {
        "output": args.output,
        "width": width,
        "height": height,
        "max_depth": args.max_depth,
        "spp": args.spp,
        "passes": args.passes,
        "mean_rgb": image.reshape(-1, 3).mean(axis=0).tolist(),
        "mean": float(image.mean()),
        "stderr_of_mean": stderr,
        "seconds": seconds,
    }
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"mean {summary['mean']:.6g} ± {stderr:.2g} (standard error, {args.passes}×{args.spp} spp), "
              f"{seconds:.1f} s -> {args.output}")


if __name__ == "__main__":
    main()
