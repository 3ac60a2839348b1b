#!/usr/bin/env python3
"""A segmentation seen in seeded random orientations, each made into a template by `medial template`.

An oblique scan places the same anatomy at a rotation to the world axes, and `medial template`
finds the medial sheet on a world-aligned grid: this checks that a template does not depend on
the orientation it happens to be given in. Each case is the input file with its header's
voxel-to-world map turned by a rotation about the grid's centre (a uniformly drawn axis, an
angle uniform in ±--max-angle degrees): the voxels, and so the staircase of the segmentation,
are the same; only their placement in the world changes. Then `medial template` with default
options on each, and one line per case: the rotation, the exit code, sheets and seams, atoms,
voxel Dice, the sampling kept, seconds; and a summary. Standard library only.

    python3 scripts/rotations.py SHAPE.nii.gz --out OUT [--count 8] [--seed 1] \\
        [--max-angle 30] [--medial target/release/medial]

Decision 0412 lists the sets measured with it (the biv-me heart).
"""

import argparse
import gzip
import math
import os
import random
import struct
import sys

from template_case import build, own_file


def read_nifti(path):
    """The file's bytes (decompressed) and its byte order ('<' or '>')."""
    opener = gzip.open if path.endswith(".gz") else open
    with opener(path, "rb") as f:
        data = bytearray(f.read())
    for order in "<>":
        if len(data) >= 348 and struct.unpack_from(order + "i", data, 0)[0] == 348:
            return data, order
    sys.exit(f"error: {path} is not a NIfTI-1 file (sizeof_hdr is not 348)")


def voxel_to_world(data, order):
    """The header's voxel-to-world map as rows [[a, b, c, d], ...] (mm): the sform, else the
    qform, else the spacings (as NIfTI's methods 3, 2, 1)."""
    sform_code, = struct.unpack_from(order + "h", data, 254)
    if sform_code > 0:
        return [list(struct.unpack_from(order + "4f", data, 280 + 16 * r)) for r in range(3)]
    pixdim = struct.unpack_from(order + "8f", data, 76)
    qform_code, = struct.unpack_from(order + "h", data, 252)
    if qform_code <= 0:
        return [[pixdim[1], 0, 0, 0], [0, pixdim[2], 0, 0], [0, 0, pixdim[3], 0]]
    b, c, d, x, y, z = struct.unpack_from(order + "6f", data, 256)
    a = math.sqrt(max(0.0, 1.0 - (b * b + c * c + d * d)))
    rot = [
        [a * a + b * b - c * c - d * d, 2 * (b * c - a * d), 2 * (b * d + a * c)],
        [2 * (b * c + a * d), a * a + c * c - b * b - d * d, 2 * (c * d - a * b)],
        [2 * (b * d - a * c), 2 * (c * d + a * b), a * a + d * d - c * c - b * b],
    ]
    qfac = -1.0 if pixdim[0] < 0 else 1.0
    scale = [pixdim[1], pixdim[2], qfac * pixdim[3]]
    return [[rot[r][k] * scale[k] for k in range(3)] + [(x, y, z)[r]] for r in range(3)]


def rotation(axis, degrees):
    """The rotation matrix by `degrees` about the unit `axis` (Rodrigues)."""
    t = math.radians(degrees)
    c, s = math.cos(t), math.sin(t)
    x, y, z = axis
    return [
        [c + x * x * (1 - c), x * y * (1 - c) - z * s, x * z * (1 - c) + y * s],
        [y * x * (1 - c) + z * s, c + y * y * (1 - c), y * z * (1 - c) - x * s],
        [z * x * (1 - c) - y * s, z * y * (1 - c) + x * s, c + z * z * (1 - c)],
    ]


def quaternion(m):
    """(b, c, d) of the unit quaternion of a proper rotation matrix, a ≥ 0."""
    trace = m[0][0] + m[1][1] + m[2][2]
    if trace > 0:
        s = 2.0 * math.sqrt(1.0 + trace)
        q = (0.25 * s, (m[2][1] - m[1][2]) / s, (m[0][2] - m[2][0]) / s, (m[1][0] - m[0][1]) / s)
    elif m[0][0] > m[1][1] and m[0][0] > m[2][2]:
        s = 2.0 * math.sqrt(1.0 + m[0][0] - m[1][1] - m[2][2])
        q = ((m[2][1] - m[1][2]) / s, 0.25 * s, (m[0][1] + m[1][0]) / s, (m[0][2] + m[2][0]) / s)
    elif m[1][1] > m[2][2]:
        s = 2.0 * math.sqrt(1.0 + m[1][1] - m[0][0] - m[2][2])
        q = ((m[0][2] - m[2][0]) / s, (m[0][1] + m[1][0]) / s, 0.25 * s, (m[1][2] + m[2][1]) / s)
    else:
        s = 2.0 * math.sqrt(1.0 + m[2][2] - m[0][0] - m[1][1])
        q = ((m[1][0] - m[0][1]) / s, (m[0][2] + m[2][0]) / s, (m[1][2] + m[2][1]) / s, 0.25 * s)
    sign = -1.0 if q[0] < 0 else 1.0
    return tuple(sign * v for v in q[1:])


def rotated(data, order, turn):
    """A copy of the file's bytes whose sform and qform are the header's map turned by `turn`
    about the grid's centre."""
    old = voxel_to_world(data, order)
    dims = struct.unpack_from(order + "8h", data, 40)
    middle = [(dims[1 + k] - 1) / 2.0 for k in range(3)]
    centre = [sum(old[r][k] * middle[k] for k in range(3)) + old[r][3] for r in range(3)]
    linear = [[sum(turn[r][j] * old[j][k] for j in range(3)) for k in range(3)] for r in range(3)]
    offset = [
        sum(turn[r][j] * (old[j][3] - centre[j]) for j in range(3)) + centre[r] for r in range(3)
    ]
    out = bytearray(data)
    for r in range(3):
        struct.pack_into(order + "4f", out, 280 + 16 * r, *linear[r], offset[r])
    # The qform: the same map as a rotation, spacings and qfac (a left-handed grid).
    norms = [math.sqrt(sum(linear[r][k] ** 2 for r in range(3))) for k in range(3)]
    direction = [[linear[r][k] / norms[k] for k in range(3)] for r in range(3)]
    det = (
        direction[0][0] * (direction[1][1] * direction[2][2] - direction[1][2] * direction[2][1])
        - direction[0][1] * (direction[1][0] * direction[2][2] - direction[1][2] * direction[2][0])
        + direction[0][2] * (direction[1][0] * direction[2][1] - direction[1][1] * direction[2][0])
    )
    qfac = -1.0 if det < 0 else 1.0
    for r in range(3):
        direction[r][2] *= qfac
    pixdim = list(struct.unpack_from(order + "8f", data, 76))
    pixdim[0], pixdim[1], pixdim[2], pixdim[3] = qfac, norms[0], norms[1], norms[2]
    struct.pack_into(order + "8f", out, 76, *pixdim)
    struct.pack_into(order + "3f", out, 256, *quaternion(direction))
    struct.pack_into(order + "3f", out, 268, *offset)
    struct.pack_into(order + "hh", out, 252, 1, 1)  # qform and sform: scanner anatomical
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("shape", help="a NIfTI-1 segmentation (.nii or .nii.gz)")
    parser.add_argument("--out", required=True, help="folder for the rotated copies and templates")
    parser.add_argument("--count", type=int, default=8, help="how many orientations [8]")
    parser.add_argument("--seed", type=int, default=1, help="seed of the draws [1]")
    parser.add_argument(
        "--max-angle", type=float, default=30.0, help="largest rotation, degrees [30]"
    )
    parser.add_argument("--medial", default="target/release/medial", help="the binary")
    args = parser.parse_args()
    if not 0 < args.count <= 1000 or not 0 <= args.max_angle <= 180:
        sys.exit("error: --count must be 1 to 1000 and --max-angle 0 to 180 degrees")
    data, order = read_nifti(args.shape)
    os.makedirs(args.out, exist_ok=True)
    draws = random.Random(args.seed)
    print(f"`{os.path.basename(args.shape)}`, seed {args.seed}, angles up to {args.max_angle}°")
    print()
    print("| case | angle (°) | axis | exit | sheets, seams | atoms | voxel Dice | kept | seconds |")
    print("|---|---|---|---|---|---|---|---|---|")
    dice, exits = [], []
    for n in range(args.count):
        axis = [draws.gauss(0.0, 1.0) for _ in range(3)]
        norm = math.sqrt(sum(a * a for a in axis))
        axis = [a / norm for a in axis]
        angle = draws.uniform(-args.max_angle, args.max_angle)
        name = f"r{n}"
        shape = os.path.join(args.out, f"{name}.nii.gz")
        with gzip.open(own_file(shape), "wb") as f:
            f.write(rotated(data, order, rotation(axis, angle)))
        code, seconds, figures, output = build(args.medial, shape, args.out, name)
        with open(own_file(os.path.join(args.out, f"{name}.log")), "w") as f:
            f.write(output)
        exits.append(code)
        cells = ["–"] * 4
        if "dice" in figures:
            dice.append(figures["dice"])
            cells = [
                f"{figures['sheets']}, {figures['seams']}",
                str(figures["atoms"]),
                f"{figures['dice']:.3f}",
                (figures.get("sampled_again") or {}).get("kept", "first"),
            ]
        axis_text = ", ".join(f"{a:.2f}" for a in axis)
        print(
            f"| {name} | {angle:.1f} | ({axis_text}) | {code} | "
            f"{' | '.join(cells)} | {seconds:.0f} |"
        )
        sys.stdout.flush()
    dice.sort()
    print()
    summary = [f"{exits.count(0)} of {len(exits)} exit 0"]
    summary.append(f"{sum(d >= 0.93 for d in dice)} at voxel Dice ≥ 0.93")
    if dice:
        summary.append(f"Dice {dice[0]:.3f}–{dice[-1]:.3f}, median {dice[len(dice) // 2]:.3f}")
    print("; ".join(summary))


if __name__ == "__main__":
    main()
