"""Writes reference .vdb files with OpenVDB itself (python3-openvdb, and vdb_tool from
libopenvdb-tools for zip and uncompressed files) for the import tests.

Usage: /usr/bin/python3 tests/vdb_make.py OUT_DIR
Prints one JSON object: file name -> list of grids, each with its name, value type, active
voxel count, active bbox, voxel size, index->world of voxel (0,0,0), and samples
[i, j, k, value, active, float32 bits of value] at voxel centres, value as OpenVDB's accessor returns it.
"""
import json
import math
import shutil
import struct
import subprocess
import sys

import pyopenvdb as vdb

out = sys.argv[1]


def blob(name="density", translation=(0.0, 0.0, 0.0), voxel=0.1, r=6, fog=True):
    g = vdb.FloatGrid()
    g.name = name
    if fog:
        g.gridClass = vdb.GridClass.FOG_VOLUME
    acc = g.getAccessor()
    for i in range(-r, r + 1):
        for j in range(-r, r + 1):
            for k in range(-r, r + 1):
                v = math.exp(-(i * i + j * j + k * k) / (0.4 * r * r))
                if v > 0.05:
                    acc.setValueOn((i + 3, j - 2, k + 5), v)
    # An inactive voxel with a non-background value: OpenVDB's accessor still returns it.
    acc.setValueOff((3, -2, 5 + r + 2), 0.3125)
    t = vdb.createLinearTransform(voxelSize=voxel)
    t.translate(translation)
    g.transform = t
    return g


def tiles():
    g = vdb.FloatGrid()
    g.name = "density"
    # A filled region: OpenVDB stores the constant 8^3 and 128^3 blocks as tiles.
    g.fill((0, 0, 0), (135, 135, 131), 0.75, True)
    acc = g.getAccessor()
    acc.setValueOn((140, 3, 4), 2.5)
    acc.setValueOn((-9, -9, -9), 0.125)
    g.transform = vdb.createLinearTransform(voxelSize=0.5)
    return g


def vec3_grid():
    g = vdb.Vec3SGrid()
    g.name = "velocity"
    g.getAccessor().setValueOn((1, 2, 3), (1.0, 2.0, 3.0))
    return g


grids_of = {}


def f32_bits(v):
    """The float32 bit pattern of a value OpenVDB returned (exact, unlike decimal JSON)."""
    return struct.unpack("<I", struct.pack("<f", v))[0]


def write(fname, grids):
    vdb.write(f"{out}/{fname}", grids=grids)
    grids_of[fname] = [g.name for g in grids]


write("blob_blosc.vdb", [blob(translation=(1.0, -2.0, 0.5))])
h = blob(translation=(0.25, 0.0, -3.0))
h.saveFloatAsHalf = True
write("blob_half.vdb", [h])
write("tiles.vdb", [tiles()])
write("two_grids.vdb", [blob(name="temperature", voxel=0.2, r=4), blob(name="density", voxel=0.05, r=5), vec3_grid()])
write("plain.vdb", [blob(translation=(-0.5, 0.5, 2.0), voxel=0.2, fog=False)])

rot = blob(name="rotated")
t = vdb.createLinearTransform(voxelSize=0.1)
t.rotate(0.3, vdb.Axis.Y)
rot.transform = t
write("rotated.vdb", [rot])
fr = blob(name="frustum")
fr.transform = vdb.createFrustumTransform(xyzMin=(0, 0, 0), xyzMax=(10, 10, 10), taper=0.5, depth=5.0)
write("frustum.vdb", [fr])

# zip and uncompressed: the Python bindings cannot choose the codec; vdb_tool can.
# (OpenVDB never zips fog volumes, so plain.vdb has no grid class.)
tool = shutil.which("vdb_tool")
if tool:
    for codec in ["zip", "none"]:
        subprocess.run([tool, "-read", f"{out}/plain.vdb", "-write", f"codec={codec}", f"{out}/plain_{codec}.vdb"],
                       check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        grids_of[f"plain_{codec}.vdb"] = grids_of["plain.vdb"]
    subprocess.run([tool, "-read", f"{out}/tiles.vdb", "-write", "codec=zip", f"{out}/tiles_zip.vdb"],
                   check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    grids_of["tiles_zip.vdb"] = grids_of["tiles.vdb"]

report = {"vdb_tool": bool(tool), "files": {}}
for fname in grids_of:
    path = f"{out}/{fname}"
    grids, _ = vdb.readAll(path)
    rg = []
    for g in grids:
        entry = {"name": g.name, "value_type": g.valueTypeName, "map": str(g.transform.typeName)}
        if g.valueTypeName == "float" and fname not in ("rotated.vdb", "frustum.vdb"):
            acc = g.getConstAccessor()
            lo, hi = g.evalActiveVoxelBoundingBox()
            ext = [hi[a] - lo[a] + 5 for a in range(3)]
            stride = 1
            while (ext[0] // stride + 1) * (ext[1] // stride + 1) * (ext[2] // stride + 1) > 30000:
                stride += 1
            samples = []
            for i in range(lo[0] - 2, hi[0] + 3, stride):
                for j in range(lo[1] - 2, hi[1] + 3, stride):
                    for k in range(lo[2] - 2, hi[2] + 3, stride):
                        v = acc.getValue((i, j, k))
                        samples.append([i, j, k, v, acc.isValueOn((i, j, k)), f32_bits(v)])
            entry.update({
                "half": bool(g.saveFloatAsHalf),
                "background": g.background,
                "active": g.activeVoxelCount(),
                "bbox": [list(lo), list(hi)],
                "voxel_size": list(g.transform.voxelSize()),
                "origin": list(g.transform.indexToWorld((0, 0, 0))),
                "samples": samples,
            })
        rg.append(entry)
    report["files"][fname] = rg
print(json.dumps(report))
