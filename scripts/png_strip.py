#!/usr/bin/env python3
"""Joins PNG images of one height side by side into one PNG, with a gap between them.

Used for the README's animation strip (frames written by `fogsmith render --frames`); only
the standard library (zlib), so it runs wherever Python does. Reads 8-bit RGB or RGBA
non-interlaced PNGs (what `fogsmith render` writes) and writes 8-bit RGB.

    python3 scripts/png_strip.py OUT.png IN1.png IN2.png ... [--gap PIXELS]
"""

import argparse
import struct
import sys
import zlib


def read_png(path):
    """(width, height, rows of RGB bytes) of an 8-bit RGB or RGBA PNG."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        sys.exit(f"{path}: not a PNG file")
    at, idat, header = 8, b"", None
    while at < len(data):
        (length,) = struct.unpack(">I", data[at : at + 4])
        kind, body = data[at + 4 : at + 8], data[at + 8 : at + 8 + length]
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat += body
        at += 12 + length
    width, height, depth, colour, _, _, interlace = header
    channels = {2: 3, 6: 4}.get(colour)
    if depth != 8 or channels is None or interlace:
        sys.exit(f"{path}: only 8-bit RGB or RGBA non-interlaced PNGs are read (re-render it with fogsmith render)")
    raw = zlib.decompress(idat)
    stride = width * channels
    rows, prior = [], bytearray(stride)
    for y in range(height):
        start = y * (stride + 1)
        kind, line = raw[start], bytearray(raw[start + 1 : start + 1 + stride])
        for i in range(stride):
            a = line[i - channels] if i >= channels else 0
            b = prior[i]
            c = prior[i - channels] if i >= channels else 0
            if kind == 1:
                line[i] = (line[i] + a) & 0xFF
            elif kind == 2:
                line[i] = (line[i] + b) & 0xFF
            elif kind == 3:
                line[i] = (line[i] + (a + b) // 2) & 0xFF
            elif kind == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 0xFF
        prior = line
        rgb = line if channels == 3 else bytearray(v for k, v in enumerate(line) if k % 4 != 3)
        rows.append(bytes(rgb))
    return width, height, rows


def write_png(path, width, height, rows):
    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    raw = b"".join(b"\x00" + r for r in rows)
    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out")
    ap.add_argument("inputs", nargs="+")
    ap.add_argument("--gap", type=int, default=4, help="pixels of black between images (default 4)")
    args = ap.parse_args()
    images = [read_png(p) for p in args.inputs]
    height = images[0][1]
    for p, (_, h, _) in zip(args.inputs, images):
        if h != height:
            sys.exit(f"{p}: {h} pixels high, the first image {height}: render every frame at one size")
    gap = b"\x00\x00\x00" * args.gap
    rows = [gap.join(rows[y] for _, _, rows in images) for y in range(height)]
    width = sum(w for w, _, _ in images) + args.gap * (len(images) - 1)
    write_png(args.out, width, height, rows)
    print(f"wrote {args.out}: {width}×{height} px from {len(images)} images")


if __name__ == "__main__":
    main()
