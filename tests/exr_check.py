"""Reads an EXR with OpenEXR's own Python bindings (PyPI `openexr`) and prints JSON:
{"size": [w, h], "header": {name: str(value)}, "channels": {name: [values, row 0 first]}}.

Usage: python3 tests/exr_check.py FILE.exr
"""
import json
import sys

import OpenEXR

with OpenEXR.File(sys.argv[1], separate_channels=True) as f:
    header = f.header()
    channels = {}
    for name, ch in f.channels().items():
        channels[name] = {"type": str(ch.pixels.dtype), "values": [float(v) for v in ch.pixels.reshape(-1)]}
    dw = header["dataWindow"]
    size = [int(dw[1][0] - dw[0][0] + 1), int(dw[1][1] - dw[0][1] + 1)]
    print(json.dumps({"size": size, "header": {k: str(v) for k, v in header.items()}, "channels": channels}))
