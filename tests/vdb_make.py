"""Writes reference .vdb files with OpenVDB itself (python3-openvdb) for the import tests.

Usage: /usr/bin/python3 tests/vdb_make.py OUT_DIR
Prints one JSON object: for each file, the grids and, for each grid, sample voxels
(index coordinates) with the value OpenVDB's accessor returns there, the active voxel
count, the active bbox and the index->world transform of a few voxels.
"""
import json
import math
import sys

import pyopenvdb as vdb

out = sys.argv[1]


def blob(name="density", translation=(0.0, 0.0, 0.0), voxel=0.1, r=6):
    g = vdb.FloatGrid()
    g.name = name
    g.gridClass = vdb.GridClass.FOG_VOLUME
    acc = g.getAccessor()
    for i in range(-r, r + 1):
        for j in range(-r, r + 1):
            for k in range(-r, r + 1):
                d2 = i * i + j * j + k * k
                v = math.exp(-d2 / (0.4 * r * r))
                if v > 0.05:
                    acc.setValueOn((i + 3, j - 2, k + 5), v)
    t = vdb.createLinearTransform(voxelSize=voxel)
    t.translate(translation)
    g.transform = t
    return g


def tiles():
    g = vdb.FloatGrid()
    g.name = "density"
    # A filled region makes OpenVDB store constant 8^3 (and 128^3) blocks as tiles.
    g.fill((0, 0, 0), (135, 15, 15), 0.75, True)
    acc = g.getAccessor()
    acc.setValueOn((140, 3, 4), 2.5)
    acc.setValueOn((-9, -9, -9), 0.125)
    g.transform = vdb.createLinearTransform(voxelSize=0.5)
    return g


files = {}


def add(fname, grids, **kw):
    path = f"{out}/{fname}"
    for g in grids:
        for key, val in kw.get("meta", {}).items():
            g[key] = val
    vdb.write(path, grids=grids)
    files[fname] = grids


add("blob_blosc.vdb", [blob(translation=(1.0, -2.0, 0.5))])
g = blob(translation=(0.25, 0.0, -3.0))
g.saveFloatAsHalf = True if hasattr(g, "saveFloatAsHalf") else None
g["is_saved_as_half_float"] = True
add("blob_half.vdb", [g])
add("tiles.vdb", [tiles()])
add("two_grids.vdb", [blob(name="temperature", voxel=0.2, r=4), blob(name="density", voxel=0.05, r=5)])

# zip and uncompressed: the Python bindings expose no compression flag, so write with
# metadata hints is impossible; use io-level options when present.
report = {}
for fname, grids in files.items():
    rg = []
    for g in vdb.readAllGridMetadata(f"{out}/{fname}"):
        pass
    for g in vdb.readAll(f"{out}/{fname}")[0]:
        acc = g.getConstAccessor()
        lo, hi = g.evalActiveVoxelBoundingBox()
        samples = []
        for i in range(lo[0] - 2, hi[0] + 3, 3):
            for j in range(lo[1] - 2, hi[1] + 3, 2):
                for k in range(lo[2] - 2, hi[2] + 3, 2):
                    samples.append([i, j, k, acc.getValue((i, j, k)), acc.isValueOn((i, j, k))])
        rg.append({
            "name": g.name,
            "active": g.activeVoxelCount(),
            "bbox": [list(lo), list(hi)],
            "voxel_size": list(g.transform.voxelSize()),
            "world": [[list(c), list(g.transform.indexToWorld(c))] for c in [(0, 0, 0), (1, 2, 3), (-5, 7, 11)]],
            "samples": samples,
        })
    report[fname] = rg
print(json.dumps(report))
