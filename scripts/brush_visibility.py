"""How visible is a brush stroke on each demo? Adds one horizontal stroke where the editor's
Paint tool puts it ("at fog depth": the first point on the ray through the grid centre where
the optical depth inside the grid reaches 0.5; noise ignored), with dabs at the brush's
spacing, renders the project before and after with `fogsmith render`, and prints the mean
luminance change (8-bit, tone-mapped PNG) over the stroke's footprint.

Usage: .venv/bin/python scripts/brush_visibility.py target/release/fogsmith [RADIUS:DENSITY ...]
(default 0.15:2, the editor's default brush). DEMOS=cloud,room limits the demos."""
import re, math, subprocess, sys, os
import numpy as np
import zlib, struct
def read_png(path):
    data = open(path, 'rb').read()
    pos = 8; idat = b''
    while pos < len(data):
        ln, typ = struct.unpack('>I4s', data[pos:pos+8]); body = data[pos+8:pos+8+ln]; pos += 12 + ln
        if typ == b'IHDR': w, h, bd, ct = struct.unpack('>IIBB', body[:10])
        elif typ == b'IDAT': idat += body
    assert bd == 8
    ch = {2: 3, 6: 4, 0: 1}[ct]
    raw = zlib.decompress(idat); stride = w * ch
    out = np.zeros((h, stride), dtype=np.int32); prev = np.zeros(stride, dtype=np.int32)
    for y in range(h):
        f = raw[y*(stride+1)]; line = np.frombuffer(raw[y*(stride+1)+1:(y+1)*(stride+1)], dtype=np.uint8).astype(np.int32)
        cur = np.zeros(stride, dtype=np.int32)
        for x in range(stride):
            a = cur[x-ch] if x >= ch else 0; b = prev[x]; c = prev[x-ch] if x >= ch else 0
            if f == 0: p = 0
            elif f == 1: p = a
            elif f == 2: p = b
            elif f == 3: p = (a + b) // 2
            else:
                pa, pb, pc = abs(b - c), abs(a - c), abs(a + b - 2*c)
                p = a if (pa <= pb and pa <= pc) else (b if pb <= pc else c)
            cur[x] = (line[x] + p) & 255
        out[y] = cur; prev = cur
    return out.reshape(h, w, ch)[..., :3].astype(float)

BIN = sys.argv[1]
cands = [tuple(map(float, c.split(':'))) for c in sys.argv[2:]] or [(0.15, 2.0)]
W = 320
import tempfile
TMP = tempfile.mkdtemp(prefix='fogsmith-brush-')

def vec(s): return np.array([float(x) for x in s.split(',')])

def render(path, out):
    subprocess.run([BIN, 'render', path, '-o', out, '--width', str(W), '--quiet'], check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return read_png(out)

def lum(img): return 0.2126*img[...,0] + 0.7152*img[...,1] + 0.0722*img[...,2]

for name in os.environ.get('DEMOS', 'cloud,cornell,room,street').split(','):
    src = open(f'projects/{name}.ron').read()
    cam = re.search(r'camera: \(position: \(([^)]*)\), target: \(([^)]*)\), up: \(([^)]*)\), fov_y_deg: ([0-9.]+)', src)
    pos, tgt, up, fov = vec(cam[1]), vec(cam[2]), vec(cam[3]), float(cam[4])
    g = re.search(r'grid: \(min: \(([^)]*)\), max: \(([^)]*)\)', src)
    gmin, gmax = vec(g[1]), vec(g[2])
    c = (gmin + gmax) / 2
    fwd = (tgt - pos); fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, up); right /= np.linalg.norm(right)
    upv = np.cross(right, fwd)
    # the editor's Fog depth: where the optical depth along the ray through the grid centre
    # reaches 0.5 (particles and base fog; noise ignored)
    parts = [(vec(m[1]), float(m[2]), float(m[3])) for m in re.finditer(r'center: \(([^)]*)\), radius: ([0-9.eE+-]+), density: ([0-9.eE+-]+)', src)]
    be = re.search(r'base_extinction: ([0-9.eE+-]+)', src); be = float(be[1]) if be else 0.0
    ray = (c - pos) / np.linalg.norm(c - pos)
    inv = 1.0 / np.where(np.abs(ray) > 1e-12, ray, 1e-12)
    t0s, t1s = (gmin - pos) * inv, (gmax - pos) * inv
    t_in = max(0.0, float(np.max(np.minimum(t0s, t1s)))); t_out = float(np.min(np.maximum(t0s, t1s)))
    def tau(t):
        # only inside the grid, as the editor's fog_depth_point reads the EV
        t = min(t, t_out)
        if t <= t_in: return 0.0
        acc = be * (t - t_in)
        for (pc, pr, pd) in parts:
            ti = float(np.dot(pc - pos, ray)); d2 = float(np.sum((pc - pos - ray * ti) ** 2))
            acc += pd * pr * math.sqrt(math.pi) / 2 * math.exp(-d2 / pr**2) * (math.erf((t - ti) / pr) - math.erf((t_in - ti) / pr))
        return acc
    tmax = 3 * float(np.linalg.norm(c - pos))
    if tau(tmax) >= 0.5:
        lo, hi = 0.0, tmax
        for _ in range(50):
            mid = (lo + hi) / 2
            lo, hi = (mid, hi) if tau(mid) < 0.5 else (lo, mid)
        c = pos + ray * lo
        print(f'{name}: fog depth {lo:.2f} m (grid centre at {np.linalg.norm((gmin+gmax)/2-pos):.2f} m)')
    depth = float(np.dot(c - pos, fwd))
    base_png = f'{TMP}/brush_{name}_base.png'
    before = render(f'projects/{name}.ron', base_png)
    H, Wd = before.shape[:2]
    aspect = Wd / H
    half_w = depth * math.tan(math.radians(fov) / 2) * aspect
    for (r, dens) in cands:
        L = 0.3 * 2 * half_w
        n = int(L / (0.5 * r)) + 1
        dabs = [c + right * (-L / 2 + i * 0.5 * r) for i in range(n)]
        txt = ''.join(f'        (id: {90000+k}, center: ({p[0]:.4f}, {p[1]:.4f}, {p[2]:.4f}), radius: {r}, density: {dens}),\n' for k, p in enumerate(dabs))
        mod = src.replace('particles: [\n', 'particles: [\n' + txt, 1)
        path = f'{TMP}/brush_{name}.ron'
        open(path, 'w').write(mod)
        after = render(path, f'{TMP}/brush_{name}_after.png')
        # footprint: pixels within r (projected) of the stroke line
        ys, xs = np.mgrid[0:H, 0:Wd]
        tanh = math.tan(math.radians(fov) / 2)
        px_per_m = (H / 2) / (depth * tanh)
        cx, cy = Wd / 2 + np.dot(c - pos, right) * px_per_m, H / 2 - np.dot(c - pos, upv) * px_per_m
        halfL = L / 2 * px_per_m
        mask = (np.abs(ys - cy) <= r * px_per_m) & (np.abs(xs - cx) <= halfL)
        lb, la = lum(before)[mask], lum(after)[mask]
        d = la - lb
        print(f'{name:8s} r={r:.2f} c={dens:4.1f} dabs={n:3d} footprint={mask.sum():5d}px '
              f'mean L before={lb.mean():6.1f} after={la.mean():6.1f} mean|dL|={np.abs(d).mean():5.1f} '
              f'rel={np.abs(d).mean()/max(lb.mean(),1):.3f}')
