#!/usr/bin/env python3
"""Synthetic two-ventricle hearts as segmentations, each made into a template by `medial template`.

Re-makes the tables of docs/decisions/0407 (issue 30): an LV wall between two circles about the
origin and an RV free wall between two circles about (cx, 0), outside the LV, extruded along z,
written as NIfTI segmentations on voxel grids moved by a fraction of a voxel; then `medial
template` with default options on each, and one line per case: exit code, sheets, seams, voxel
Dice, seconds. Standard library only.

    python3 scripts/ventricles.py --out OUT [--medial target/release/medial]
"""

import argparse
import math
import os
import struct
import sys

from template_case import build, own_file

# (name, voxel mm, LV inner/outer radius, RV inner/outer radius, RV centre x, height, phase)
CASES = [
    ("4mm-rv-0", 1.0, 12, 20, 16, 20, 16, 24, (0.0, 0.0, 0.0)),
    ("4mm-rv-half", 1.0, 12, 20, 16, 20, 16, 24, (0.5, 0.5, 0.5)),
    ("4mm-rv-quarter", 1.0, 12, 20, 16, 20, 16, 24, (0.25, 0.25, 0.5)),
    ("4mm-rv-x", 1.0, 12, 20, 16, 20, 16, 24, (0.5, 0.0, 0.5)),
    ("4mm-rv-y", 1.0, 12, 20, 16, 20, 16, 24, (0.0, 0.5, 0.5)),
    ("4mm-rv-a", 1.0, 12, 20, 16, 20, 16, 24, (0.75, 0.1, 0.3)),
    ("4mm-rv-b", 1.0, 12, 20, 16, 20, 16, 24, (0.1, 0.8, 0.6)),
    ("larger", 1.0, 14, 22, 17, 21, 16, 30, (0.3, 0.6, 0.2)),
    ("3.5mm-rv", 1.0, 12, 20, 16.5, 20, 14, 24, (0.3, 0.6, 0.2)),
    ("long", 1.0, 15, 24, 20, 24, 20, 40, (0.3, 0.6, 0.2)),
    ("small-3mm-rv", 1.0, 12, 19, 15, 18, 15, 24, (0.3, 0.6, 0.2)),
    ("0.8mm-voxels", 0.8, 12, 20, 17, 20, 16, 24, (0.3, 0.6, 0.2)),
    ("3mm-rv", 1.0, 12, 20, 17, 20, 16, 24, (0.5, 0.5, 0.5)),
    ("2mm-rv", 1.0, 12, 20, 18, 20, 16, 24, (0.5, 0.5, 0.5)),
    ("1.5mm-rv-0.5mm-voxels", 0.5, 12, 20, 18.5, 20, 16, 24, (0.5, 0.5, 0.5)),
]


def segmentation(h, lv_in, lv_out, rv_in, rv_out, cx, height, phase):
    """The voxels (x fastest) and the grid: dims and the first voxel centre (mm)."""
    lo = (-lv_out - 4.0, -max(lv_out, rv_out) - 4.0, -height / 2 - 4.0)
    hi = (cx + rv_out + 4.0, max(lv_out, rv_out) + 4.0, height / 2 + 4.0)
    dims = [math.ceil((hi[d] - lo[d]) / h) for d in range(3)]
    first = [lo[d] + phase[d] * h for d in range(3)]
    data = bytearray(dims[0] * dims[1] * dims[2])
    n = 0
    for k in range(dims[2]):
        z = first[2] + k * h
        for j in range(dims[1]):
            y = first[1] + j * h
            for i in range(dims[0]):
                x = first[0] + i * h
                lv, rv = math.hypot(x, y), math.hypot(x - cx, y)
                wall = lv <= lv_out or rv <= rv_out
                cavity = lv < lv_in or (rv < rv_in and lv > lv_out)
                data[n] = 1 if wall and not cavity and abs(z) <= height / 2 else 0
                n += 1
    return bytes(data), dims, first


def write_nifti(path, data, dims, first, h):
    """A NIfTI-1 file of uint8 voxels with its sform (scanner coordinates, mm)."""
    header = bytearray(348)
    struct.pack_into("<i", header, 0, 348)
    struct.pack_into("<8h", header, 40, 3, dims[0], dims[1], dims[2], 1, 1, 1, 1)
    struct.pack_into("<hh", header, 70, 2, 8)  # datatype uint8, 8 bits
    struct.pack_into("<8f", header, 76, 1.0, h, h, h, 1.0, 1.0, 1.0, 1.0)
    struct.pack_into("<f", header, 108, 352.0)  # vox_offset
    struct.pack_into("<f", header, 112, 1.0)  # scl_slope
    header[123] = 2  # xyzt_units: mm
    struct.pack_into("<hh", header, 252, 0, 1)  # qform_code 0, sform_code 1 (scanner)
    struct.pack_into("<4f", header, 280, h, 0.0, 0.0, first[0])
    struct.pack_into("<4f", header, 296, 0.0, h, 0.0, first[1])
    struct.pack_into("<4f", header, 312, 0.0, 0.0, h, first[2])
    header[344:348] = b"n+1\0"
    with open(own_file(path), "wb") as f:
        f.write(header + bytes(4) + data)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", required=True, help="folder for the segmentations and templates")
    parser.add_argument("--medial", default="target/release/medial", help="the binary")
    args = parser.parse_args()
    os.makedirs(args.out, exist_ok=True)
    print("| case | voxel | LV | RV | cx | phase | exit | sheets, seams | voxel Dice | seconds |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, h, lv_in, lv_out, rv_in, rv_out, cx, height, phase in CASES:
        data, dims, first = segmentation(h, lv_in, lv_out, rv_in, rv_out, cx, height, phase)
        shape = os.path.join(args.out, f"{name}.nii")
        write_nifti(shape, data, dims, first, h)
        code, seconds, figures, _ = build(args.medial, shape, args.out, name)
        found = f"{figures.get('sheets', '–')}, {figures.get('seams', '–')}"
        dice = f"{figures['dice']:.3f}" if "dice" in figures else "–"
        print(
            f"| {name} | {h} | {lv_in} / {lv_out} | {rv_in} / {rv_out} | {cx} | "
            f"{', '.join(str(p) for p in phase)} | {code} | {found} | {dice} | "
            f"{seconds:.1f} |"
        )
        sys.stdout.flush()


if __name__ == "__main__":
    main()
