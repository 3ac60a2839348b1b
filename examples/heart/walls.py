"""Helpers of examples/heart/run.sh (standard library only).

  walls.py centre TEMPLATE.vtk          the mean of the template's boundary points
  walls.py affine "X Y Z" C             a 4x4 scaling by C about the point (X, Y, Z), row by row
  walls.py walls OUT FRAMES             per wall and frame, the thickness ratio to the template
"""
import csv
import json
import statistics
import sys


def vtk_tokens(path):
    with open(path) as f:
        return f.read().split()


def points(tokens):
    i = tokens.index("POINTS")
    n = int(tokens[i + 1])
    v = [float(x) for x in tokens[i + 3:i + 3 + 3 * n]]
    return [v[3 * k:3 * k + 3] for k in range(n)]


def point_array(tokens, name):
    """A one-component point array of an ASCII legacy VTK file: `SCALARS NAME TYPE 1` and its
    `LOOKUP_TABLE` line, or a field array `NAME 1 COUNT TYPE`."""
    n = int(tokens[tokens.index("POINT_DATA") + 1])
    i = tokens.index(name)
    start = i + 5 if tokens[i - 1] == "SCALARS" else i + 4
    return [float(x) for x in tokens[start:start + n]]


def centre(path):
    p = points(vtk_tokens(path))
    print(" ".join(f"{sum(c[k] for c in p) / len(p):.6f}" for k in range(3)))


def affine(centre_text, c):
    x, y, z = (float(v) for v in centre_text.split())
    c = float(c)
    t = [(1 - c) * x, (1 - c) * y, (1 - c) * z]
    rows = [[c, 0, 0, t[0]], [0, c, 0, t[1]], [0, 0, c, t[2]], [0, 0, 0, 1]]
    print("\n".join(" ".join(f"{v:.9g}" for v in r) for r in rows))


WALLS = {0: "sheet 0", 1: "sheet 1", 2: "sheet 2"}


def walls(out, frames):
    tokens = vtk_tokens(f"{out}/template.vtk")
    atom_of = [int(v) for v in point_array(tokens, "MedialIndex")]
    sheet_of = [int(v) for v in point_array(tokens, "Sheet")]
    spoke = point_array(tokens, "Radius")
    wall, spokes = {}, {}
    for a, s, r in zip(atom_of, sheet_of, spoke):
        wall[a] = s
        spokes.setdefault(a, []).append(r)
    # The template's own thickness (2 x mean spoke, as atoms.csv's): atoms.csv's thickness_t0
    # is the template's after the fit's initial alignment, whose scale takes the shape's size.
    template_thickness = {a: 2 * statistics.fmean(r) for a, r in spokes.items()}
    rows = []
    for k in range(1, frames + 1):
        scale = 1 - 0.1 * k / frames
        # The planted ratio per atom: the spoke factor applied (thickening.csv) times the
        # affine part's scaling.
        with open(f"{out}/frame{k}/thickening.csv") as f:
            planted = {int(r["atom"]): float(r["factor"]) * scale for r in csv.DictReader(f)}
        with open(f"{out}/fit{k}/atoms.csv") as f:
            ratios, truth = {}, {}
            for r in csv.DictReader(f):
                a = int(r["atom"])
                t0, t1 = template_thickness[a], float(r["thickness_t1"])
                ratios.setdefault(wall[a], []).append(t1 / t0)
                truth.setdefault(wall[a], []).append(planted[a])
        with open(f"{out}/fit{k}/summary.json") as f:
            fit = json.load(f)
        for w in sorted(ratios):
            v, p = ratios[w], truth[w]
            rows.append({
                "frame": k,
                "planted_ratio": statistics.fmean(p),
                "wall": "seam" if w < 0 else f"sheet {w}",
                "atoms": len(v),
                "mean_ratio": statistics.fmean(v),
                "min_ratio": min(v),
                "max_ratio": max(v),
                "mean_abs_error": statistics.fmean(abs(a - b) for a, b in zip(v, p)),
                "fit_voxel_dice": fit["final"]["voxel_dice"],
                "fit_max_angle_deg": fit["final"]["max_spoke_normal_deg"],
                "fit_max_mismatch_pct": fit["final"]["max_spoke_mismatch_pct"],
            })
    with open(f"{out}/walls.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print("| frame | wall | atoms | planted ratio (mean) | fitted ratio mean (min–max) | "
          "mean per-atom error | fit voxel Dice |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['frame']} | {r['wall']} | {r['atoms']} | {r['planted_ratio']:.3f} | "
              f"{r['mean_ratio']:.3f} ({r['min_ratio']:.3f}–{r['max_ratio']:.3f}) | "
              f"{r['mean_abs_error']:.3f} | {r['fit_voxel_dice']:.3f} |")
    series = {"file-series-version": "1.0",
              "files": [{"name": "template.vtk", "time": 0}] +
                       [{"name": f"fit{k}/fitted_template.vtk", "time": k}
                        for k in range(1, frames + 1)]}
    with open(f"{out}/cycle.vtk.series", "w") as f:
        json.dump(series, f, indent=1)
    plot(out, rows, frames)


def plot(out, rows, frames):
    """walls.svg: the mean thickness ratio of each wall over the frames, fitted (solid) and
    planted (dashed)."""
    w, h, m, labels = 560, 320, 50, 80
    values = [r[k] for r in rows for k in ("mean_ratio", "planted_ratio")]
    lo = min(1.0, min(values)) - 0.05
    hi = max(values) + 0.05
    x = lambda k: m + (w - 2 * m - labels) * k / frames
    y = lambda v: h - m - (h - 2 * m) * (v - lo) / (hi - lo)
    colours = ["#e6194b", "#3cb44b", "#0082c8", "#888888"]
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}">',
             f'<rect width="{w}" height="{h}" fill="white"/>',
             f'<line x1="{m}" y1="{h - m}" x2="{w - m - labels}" y2="{h - m}" stroke="black"/>',
             f'<line x1="{m}" y1="{m}" x2="{m}" y2="{h - m}" stroke="black"/>',
             f'<text x="{(w - labels) / 2}" y="{h - 10}" text-anchor="middle">frame (0: the template; '
             f'dashed: planted)</text>',
             f'<text x="12" y="{h / 2}" transform="rotate(-90 12 {h / 2})" '
             f'text-anchor="middle">mean thickness ratio</text>']
    for k in range(frames + 1):
        parts.append(f'<text x="{x(k)}" y="{h - m + 16}" text-anchor="middle">{k}</text>')
    for v in (lo + 0.05, (lo + hi) / 2, hi - 0.05):
        parts.append(f'<text x="{m - 6}" y="{y(v) + 4}" text-anchor="end">{v:.2f}</text>')
    names = sorted({r["wall"] for r in rows})
    for i, name in enumerate(names):
        pts = [(0, 1.0)] + [(r["frame"], r["mean_ratio"]) for r in rows if r["wall"] == name]
        path = " ".join(f"{x(k):.1f},{y(v):.1f}" for k, v in pts)
        c = colours[i % len(colours)]
        parts.append(f'<polyline points="{path}" fill="none" stroke="{c}" stroke-width="2"/>')
        planted = [(0, 1.0)] + [(r["frame"], r["planted_ratio"]) for r in rows
                                if r["wall"] == name]
        dashed = " ".join(f"{x(k):.1f},{y(v):.1f}" for k, v in planted)
        parts.append(f'<polyline points="{dashed}" fill="none" stroke="{c}" stroke-width="1" '
                     f'stroke-dasharray="4 3"/>')
        parts.append(f'<text x="{x(frames) + 6}" y="{y(pts[-1][1]) + 4}" fill="{c}">{name}</text>')
    parts.append("</svg>")
    with open(f"{out}/walls.svg", "w") as f:
        f.write("\n".join(parts))


if __name__ == "__main__":
    command = sys.argv[1]
    if command == "centre":
        centre(sys.argv[2])
    elif command == "affine":
        affine(sys.argv[2], sys.argv[3])
    elif command == "walls":
        walls(sys.argv[2], int(sys.argv[3]))
    else:
        sys.exit(f"unknown command {command}")
