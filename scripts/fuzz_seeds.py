#!/usr/bin/env python3
"""Seed corpora for the fuzz targets (fuzz/), from the files the project ships.

map_image: the floor-plan pictures and small PNGs of the repository; map_import: each shipped
ROS map as the target reads it (u16 little-endian YAML length, the YAML naming `map.pgm`, the
image); wire_decode: fuzz/seeds/wire_decode (the codec's fixtures, kept current by
protocol/tests/wire.rs); scenario: every scenario YAML. Usage: fuzz_seeds.py OUT_DIR
"""
import glob
import os
import re
import shutil
import struct
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# Shipped plans are 130-450 KB; the smaller ones keep the fuzzer's inputs short.
MAX_IMAGE_BYTES = 260_000


def put(out, target, name, data):
    d = os.path.join(out, target)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, name), "wb") as f:
        f.write(data)


def main():
    out = sys.argv[1]
    maps = sorted(glob.glob(os.path.join(ROOT, "sim/scenarios/maps/*.yaml")))
    pictures = [p for p in sorted(glob.glob(os.path.join(ROOT, "sim/scenarios/maps/*.pgm")))
                if os.path.getsize(p) <= MAX_IMAGE_BYTES]
    pictures += sorted(glob.glob(os.path.join(ROOT, "planning/tests/golden/*.png")))
    pictures += sorted(glob.glob(os.path.join(ROOT, "models/checks/frame_0[0-2]_*.png")))
    for p in pictures:
        put(out, "map_image", os.path.basename(p), open(p, "rb").read())
    for y in maps:
        text = open(y).read()
        m = re.search(r"^image:\s*(\S+)", text, re.M)
        if not m:
            continue
        image = os.path.join(os.path.dirname(y), m.group(1).strip("'\""))
        if not os.path.exists(image) or os.path.getsize(image) > MAX_IMAGE_BYTES:
            continue
        yaml = re.sub(r"^image:.*$", "image: map.pgm", text, flags=re.M).encode()
        put(out, "map_import", os.path.basename(y) + ".bin",
            struct.pack("<H", len(yaml)) + yaml + open(image, "rb").read())
    for s in sorted(glob.glob(os.path.join(ROOT, "fuzz/seeds/wire_decode/*.bin"))):
        put(out, "wire_decode", os.path.basename(s), open(s, "rb").read())
    for s in sorted(glob.glob(os.path.join(ROOT, "sim/scenarios/*.yaml"))):
        put(out, "scenario", os.path.basename(s), open(s, "rb").read())
    for t in ("map_image", "map_import", "wire_decode", "scenario"):
        d = os.path.join(out, t)
        n = len(os.listdir(d)) if os.path.isdir(d) else 0
        print(f"{t}: {n} seed files")
        if n == 0:
            sys.exit(f"no seeds for {t}")


if __name__ == "__main__":
    main()
