#!/usr/bin/env python3
"""Top view of a plane map as a PNG (docs/img/street_map.png).

Usage: street_map.py DIR OUT_PNG [WIDTH]

DIR is a `planeslam run` output (plane_map.json and trajectory_tum.txt: the map and the estimated
trajectory) or a `planeslam simulate street` folder (planes.json and poses.txt: the ground-truth
planes and route). Planes are drawn seen from above: near-horizontal planes (road, sidewalks)
filled and faded, the others (facades, kerbs, cars) as their outlines' footprints; the trajectory
in black. Standard library only (zlib for the PNG)."""
import json
import pathlib
import struct
import sys
import zlib


def write_png(path, width, height, pixels):
    rows = b"".join(b"\x00" + bytes(pixels[y * width * 3:(y + 1) * width * 3])
                    for y in range(height))

    def chunk(kind, data):
        return (struct.pack(">I", len(data)) + kind + data +
                struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))

    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    pathlib.Path(path).write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) +
                                   chunk(b"IDAT", zlib.compress(rows, 9)) + chunk(b"IEND", b""))


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    run = pathlib.Path(sys.argv[1])
    width = int(sys.argv[3]) if len(sys.argv) > 3 else 900
    track = []
    if (run / "plane_map.json").exists():
        planes = json.loads((run / "plane_map.json").read_text())["planes"]
        for line in (run / "trajectory_tum.txt").read_text().splitlines():
            v = line.split()
            if len(v) == 8:
                track.append((float(v[1]), float(v[2])))
    else:
        planes = json.loads((run / "planes.json").read_text())["planes"]
        for p in planes:
            h = (p["id"] * 2654435761) & 0xFFFFFF
            p["color"] = [40 + (h & 0x9F), 40 + ((h >> 8) & 0x9F), 40 + ((h >> 16) & 0x9F)]
        for line in (run / "poses.txt").read_text().splitlines():
            v = line.split()
            if len(v) == 12:
                track.append((float(v[3]), float(v[7])))
    xs = [p[0] for pl in planes for poly in pl["polygons"] for p in poly] + [t[0] for t in track]
    ys = [p[1] for pl in planes for poly in pl["polygons"] for p in poly] + [t[1] for t in track]
    x0, x1, y0, y1 = min(xs) - 5, max(xs) + 5, min(ys) - 5, max(ys) + 5
    scale = width / (x1 - x0)
    height = int((y1 - y0) * scale) + 1
    img = bytearray([255] * (width * height * 3))

    def to_px(x, y):
        return (x - x0) * scale, (y1 - y) * scale

    def put(u, v, rgb, alpha=1.0):
        if 0 <= u < width and 0 <= v < height:
            k = 3 * (v * width + u)
            for c in range(3):
                img[k + c] = int(img[k + c] * (1 - alpha) + rgb[c] * alpha)

    def line(a, b, rgb, thick=1):
        (ua, va), (ub, vb) = a, b
        n = int(max(abs(ub - ua), abs(vb - va))) + 1
        for i in range(n + 1):
            t = i / n
            u, v = int(ua + t * (ub - ua)), int(va + t * (vb - va))
            for du in range(thick):
                for dv in range(thick):
                    put(u + du, v + dv, rgb)

    def fill(poly, rgb, alpha):
        pts = [to_px(p[0], p[1]) for p in poly]
        vmin, vmax = max(0, int(min(p[1] for p in pts))), min(height - 1, int(max(p[1] for p in pts)))
        for v in range(vmin, vmax + 1):
            yc = v + 0.5
            cross = []
            for i in range(len(pts)):
                (ua, va), (ub, vb) = pts[i], pts[(i + 1) % len(pts)]
                if (va <= yc) != (vb <= yc):
                    cross.append(ua + (yc - va) / (vb - va) * (ub - ua))
            cross.sort()
            for i in range(0, len(cross) - 1, 2):
                for u in range(max(0, int(cross[i])), min(width, int(cross[i + 1]) + 1)):
                    put(u, v, rgb, alpha)

    horizontal = [p for p in planes if abs(p["normal"][2]) > 0.9]
    others = [p for p in planes if abs(p["normal"][2]) <= 0.9]
    for p in horizontal:
        for poly in p["polygons"]:
            fill(poly, p["color"], 0.35)
    for p in others:
        for poly in p["polygons"]:
            pts = [to_px(q[0], q[1]) for q in poly]
            for i in range(len(pts)):
                line(pts[i], pts[(i + 1) % len(pts)], p["color"], 2)
    for a, b in zip(track, track[1:]):
        line(to_px(*a), to_px(*b), (0, 0, 0), 2)
    write_png(sys.argv[2], width, height, img)
    print(f"{sys.argv[2]}: {width} x {height}, {len(planes)} planes, {len(track)} poses")


if __name__ == "__main__":
    main()
