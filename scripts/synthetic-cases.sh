#!/usr/bin/env bash
# The table of automatic fits of synthetic cases (issue 29; docs/fit.md, "Figures of automatic
# fits"): the shipped toy, cup and t001-bent, "hard" and three warps of cmrep's t001 made by
# `medial synth --from`, and the placenta, each fitted without a config by --image, --target
# and --surface where listed; the shipped configs examples/*/fit.toml as the hand-tuned column.
#
#   bash scripts/synthetic-cases.sh [OUT] [--data DATA] [--skip-hand-tuned]
#
# OUT: the results (default target/synthetic-cases under the repository root); DATA: the shared
# data folder (default ../shared/data beside the repository root). Each fit goes to
# OUT/<case>/<fit>/, the commands and their stderr to OUT/<case>.log, and OUT/table.md holds the
# table (also printed at the end). Surfaces are the target boundary midpoint-subdivided, its
# vertices and triangles shuffled (seeded), written as OBJ. A fit that fails is a cell with its
# exit code and status; the script goes on. The figures are read from each fit's summary.json.
set -euo pipefail

usage() {
  sed -n '2,14p' "$0" | sed 's/^# \{0,1\}//'
}

root="$(cd "$(dirname "$0")/.." && pwd)"
hand_tuned=1
data="$root/../shared/data"
positional=()
while [ "$#" -gt 0 ]; do
  case "$1" in
    --skip-hand-tuned) hand_tuned=0 ;;
    --data) data="${2:?--data needs a folder}"; shift ;;
    -h | --help) usage; exit 0 ;;
    -*) echo "synthetic-cases.sh: unknown option '$1'" >&2; usage >&2; exit 2 ;;
    *) positional+=("$1") ;;
  esac
  shift
done
if [ "${#positional[@]}" -gt 1 ]; then
  echo "synthetic-cases.sh: at most one path (OUT)" >&2
  exit 2
fi
out="${positional[0]:-$root/target/synthetic-cases}"
# shellcheck source=scripts/cases-lib.sh
source "$root/scripts/cases-lib.sh"
absolute_folders synthetic-cases.sh cmrep/t001_template_bcmrep.vtk
build_medial

# surface MESH.vtk OUT.obj: MESH (legacy ASCII VTK polydata, triangles) midpoint-subdivided, its
# vertices and triangles shuffled and each triangle's corners rotated (seed 1), written as OBJ.
surface() {
  python3 - "$1" "$2" <<'PY'
import random, sys
src, dst = sys.argv[1:3]
tok = open(src).read().split()
i = tok.index("POINTS")
n = int(tok[i + 1])
xyz = [float(v) for v in tok[i + 3:i + 3 + 3 * n]]
pts = [tuple(xyz[3 * k:3 * k + 3]) for k in range(n)]
i = tok.index("POLYGONS")
m = int(tok[i + 1])
tris, j = [], i + 3
for _ in range(m):
    c = int(tok[j])
    if c != 3:
        sys.exit("not a triangle mesh: " + src)
    tris.append(tuple(int(v) for v in tok[j + 1:j + 4]))
    j += 4
mid = {}
def midpoint(a, b):
    key = (min(a, b), max(a, b))
    if key not in mid:
        mid[key] = len(pts)
        pts.append(tuple((pts[a][d] + pts[b][d]) / 2 for d in range(3)))
    return mid[key]
fine = []
for a, b, c in tris:
    ab, bc, ca = midpoint(a, b), midpoint(b, c), midpoint(c, a)
    fine += [(a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca)]
rng = random.Random(1)
order = list(range(len(pts)))
rng.shuffle(order)
new_of = [0] * len(pts)
for new, old in enumerate(order):
    new_of[old] = new
rng.shuffle(fine)
with open(dst, "w") as f:
    for old in order:
        f.write("v %.17g %.17g %.17g\n" % pts[old])
    for t in fine:
        r = rng.randrange(3)
        t = t[r:] + t[:r]
        f.write("f %d %d %d\n" % tuple(new_of[v] + 1 for v in t))
PY
}

# fit NAME DIR ARGS...: one fit into DIR (`medial fit ARGS --out DIR`); prints its cell.
fit() {
  local name="$1" dir="$2" rc=0 start wall
  shift 2
  failed_step=""
  start="$(date +%s.%N)"
  run "$name" "$dir.json" "$medial" fit "$@" --out "$dir" --quiet || rc=$?
  wall="$(python3 -c "import sys; print(format(float(sys.argv[2]) - float(sys.argv[1]), '.1f'))" "$start" "$(date +%s.%N)")"
  echo "synthetic-cases.sh: $case $name exit $rc after $wall s" >&2
  cell "$dir/summary.json" "$rc" "$log"
}

# cell SUMMARY RC LOG: the table's cell of one fit.
cell() {
  python3 -c '
import json, os, sys
summary, rc, log = sys.argv[1:4]
def num(x):
    return format(x, ".2f" if abs(x) >= 0.1 else ".3f" if abs(x) >= 0.01 else ".4f")
if not os.path.isfile(summary):
    errs = [l.strip() for l in open(log, errors="replace") if l.lower().startswith("error")]
    print("exit " + rc + (": " + errs[-1][:200] if errs else ""))
    sys.exit()
d = json.load(open(summary))
f = d.get("final", {})
parts = []
if f.get("voxel_dice") is not None:
    parts.append("voxel Dice " + format(f["voxel_dice"], ".3f"))
elif f.get("surface_distance") is not None:
    parts.append(format(f["surface_distance"], ".3f") + " mm to the surface")
elif f.get("mean_distance") is not None:
    parts.append(format(f["mean_distance"], ".3f") + " mm to the points")
for key, unit in (("max_spoke_normal_deg", "°"), ("max_spoke_mismatch_pct", " %")):
    if f.get(key) is not None:
        parts.append(num(f[key]) + unit)
parts.append(format(d.get("evaluations", 0), ",") + " evaluations")
parts.append(format(d.get("seconds", 0), ".1f") + " s")
status = d.get("status", "?")
text = ", ".join(parts) + " (" + status + ")"
if rc != "0":
    text = "**exit " + rc + "**: " + text
print(text.replace("|", "\\|"))
' "$@"
}

# auto DIR ARGS...: the automatic fit's cell of the current case.
auto() {
  local dir="$1"
  shift
  fit auto "$dir" "$@"
}

# tuned CONFIG DIR: the shipped config's cell, or — with --skip-hand-tuned.
tuned() {
  if [ "$hand_tuned" -eq 1 ]; then
    fit hand-tuned "$2" "$1"
  else
    echo "not run (--skip-hand-tuned)"
  fi
}

# synth NAME ARGS...: `medial synth --from t001 ARGS` into OUT/NAME/case.
synth() {
  local name="$1"
  shift
  run synth "$out/$name/synth.json" "$medial" synth --from "$data/cmrep/t001_template_bcmrep.vtk" \
    --out "$out/$name/case" --quiet "$@"
}

rows=()
# row CASE DESCRIPTION AUTO TUNED
row() {
  rows+=("| $2 | $3 | $4 |")
}

begin() {
  case="$1"
  log="$out/$case.log"
  rm -rf "${out:?}/$case"
  mkdir -p "$out/$case"
  : >"$log"
  echo "synthetic-cases.sh: $case ..." >&2
}

# The shipped cases: their template, target image and target points as shipped.
for c in toy cup t001-bent; do
  begin "$c"
  ex="$root/examples/$c"
  surface "$ex/target_boundary.vtk" "$out/$c/surface.obj"
  image="$(auto "$out/$c/image" --template "$ex/template.vtk" --image "$ex/target.nii.gz")"
  row "$c" "$c, \`--image\`" "$image" "$(tuned "$ex/fit.toml" "$out/$c/image-tuned")"
  if [ "$c" != cup ]; then
    points="$(auto "$out/$c/target" --template "$ex/template.vtk" --target "$ex/target_boundary.vtk")"
    if [ "$c" = t001-bent ]; then
      row "$c" "$c, \`--target\`" "$points" "$(tuned "$ex/fit_boundary.toml" "$out/$c/target-tuned")"
    else
      row "$c" "$c, \`--target\`" "$points" "—"
    fi
  fi
  row "$c" "$c, \`--surface\`" "$(auto "$out/$c/surface" --template "$ex/template.vtk" --surface "$out/$c/surface.obj")" "—"
done

# t001 under `medial synth --from`: "hard" and three warps. AFFINE is a 4×4 world matrix about
# the template's centre (docs/synth.md); empty: the default affine part.
warp_case() {
  local name="$1" description="$2" affine="$3" c="$out/$1/case" failed=0
  shift 3
  begin "$name"
  if [ -n "$affine" ]; then
    printf '%s\n' "$affine" >"$out/$name/affine.txt"
    synth "$name" "$@" --affine "$out/$name/affine.txt" || failed=$?
  else
    synth "$name" "$@" || failed=$?
  fi
  if [ "$failed" -ne 0 ]; then
    row "$name" "$description, all" "\`medial synth\` exit $failed (see $name.log)" "—"
    return 0
  fi
  local kinds=(image target)
  if [ "$name" = hard ]; then
    surface "$c/target_boundary.vtk" "$out/$name/surface.obj"
    kinds+=(surface)
  fi
  for kind in "${kinds[@]}"; do
    case "$kind" in
      image) flag=(--image "$c/target.nii.gz") ;;
      target) flag=(--target "$c/target_boundary.vtk") ;;
      surface) flag=(--surface "$out/$name/surface.obj") ;;
    esac
    row "$name" "$description, \`--$kind\`" "$(auto "$out/$name/$kind" --template "$c/template.vtk" "${flag[@]}")" "—"
  done
}

warp_case hard "hard (bend −35°, twist 25°, scaling 1.15, 0.9, 1.05)" \
  "1.15 0 0 0
0 0.9 0 0
0 0 1.05 0
0 0 0 1" --bend -35 --twist 25
warp_case warp-mild "warp mild (bend 10°, twist 5°, the default affine part)" "" --bend 10 --twist 5
warp_case warp-scaled "warp (bend −25°, twist 20°, scaling 1.1, 0.95, 1)" \
  "1.1 0 0 0
0 0.95 0 0
0 0 1 0
0 0 0 1" --bend -25 --twist 20
warp_case warp-turned "warp (bend 35°, a 15° rotation about z, a shift (2, 1, −1) mm)" \
  "0.965925826289068 -0.258819045102521 0 2
0.258819045102521 0.965925826289068 0 1
0 0 1 -1
0 0 0 1" --bend 35

# The placenta: cmrep's sheet inflated, against its deformed template as a shuffled surface.
begin placenta
if run inflate "$out/placenta/inflate.json" "$medial" inflate --subdivide 1 \
  "$data/cmrep/placenta_template_anterioralign3.vtk" --out "$out/placenta/template.vtk"; then
  surface "$data/cmrep/placenta_template_def_to_target.vtk" "$out/placenta/surface.obj"
  row placenta "placenta (\`medial inflate --subdivide 1\`), \`--surface\`" \
    "$(auto "$out/placenta/surface" --template "$out/placenta/template.vtk" --surface "$out/placenta/surface.obj")" "—"
else
  row placenta "placenta, \`--surface\`" "\`medial inflate\` exit (see placenta.log)" "—"
fi

{
  echo "Made by \`bash scripts/synthetic-cases.sh\` on $(date -u '+%Y-%m-%d %H:%M UTC'), $("$medial" --version), commit $(commit_of_root),"
  echo "$(nproc) cores, load average at the end $(cut -d' ' -f1-3 /proc/loadavg 2>/dev/null || echo unknown)."
  echo "Angle and mismatch: the largest spoke–normal angle and spoke mismatch at the end of the fit."
  echo
  echo "| case | automatic | hand-tuned |"
  echo "|---|---|---|"
  printf '%s\n' "${rows[@]}"
} >"$out/table.md"
echo
cat "$out/table.md"
