"""Opens a .vdb file with OpenVDB itself (python3-openvdb) and prints what it reads as JSON.

Usage: /usr/bin/python3 tests/vdb_check.py FILE.vdb NX NY NZ
For every grid: name, value type, half flag, class, creator, light metadata, active voxel
count (tiles included), leaf count, active bbox, voxel size, index->world of a few voxels,
and the float32 bit pattern of the value OpenVDB's accessor returns at every voxel of [0,NX)x[0,NY)x[0,NZ), x fastest
(a list of three for a vec3s grid).
"""
import json
import struct
import sys

import pyopenvdb as vdb


def bits(v):
    return struct.unpack("<I", struct.pack("<f", v))[0]


path = sys.argv[1]
nx, ny, nz = (int(a) for a in sys.argv[2:5])
grids, file_meta = vdb.readAll(path)
out = {"file_metadata": {k: str(v) for k, v in file_meta.items()}, "grids": []}
for g in grids:
    acc = g.getConstAccessor()
    lo, hi = g.evalActiveVoxelBoundingBox()
    meta = {}
    for k in g.metadata.keys():
        v = g[k]
        meta[k] = list(v) if isinstance(v, tuple) else v
    values = []
    active = []
    for k in range(nz):
        for j in range(ny):
            for i in range(nx):
                v = acc.getValue((i, j, k))
                values.append([bits(c) for c in v] if isinstance(v, tuple) else bits(v))
                active.append(acc.isValueOn((i, j, k)))
    out["grids"].append({
        "name": g.name,
        "value_type": g.valueTypeName,
        "half": bool(g.saveFloatAsHalf),
        "background": g.background,
        "meta": meta,
        "active": g.activeVoxelCount(),
        "leaves": g.leafCount(),
        "bbox": [list(lo), list(hi)],
        "voxel_size": list(g.transform.voxelSize()),
        "world": [[list(c), list(g.transform.indexToWorld(c))] for c in [(0, 0, 0), (1, 2, 3), (nx - 1, ny - 1, nz - 1)]],
        "values": values,
        "active_mask": active,
    })
print(json.dumps(out))
