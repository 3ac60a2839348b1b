#!/usr/bin/env bash
# A biventricular study from one command (issue 30): the medial template of biv-me's template
# heart (a 1 mm segmentation; three sheets — LV free wall, RV free wall, septum — meeting along
# the RV insertion seam), a synthetic cycle made from it (walls thickened by up to 1.575, about
# the LV's ED -> ES ratio: the CAP meshes' own 1.53 in examples/lv, limited by the tool where a wall would cross itself;
# shrunk towards the centre by up to 10 %; twisted up to 12 degrees: every atom's thickness
# change known), each frame fitted by the automatic fit, and the per-atom thickness change over
# the cycle by wall against the planted one.
#   bash examples/heart/run.sh        # from anywhere; writes only examples/heart/out/
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
here="$root/examples/heart"
out="$here/out"
data="${HEART_DATA:-$root/../shared/data/bivme}"
target="${CARGO_TARGET_DIR:-$root/target}"
(cd "$root" && cargo build --release -q -p medial-cli)
medial="$target/release/medial"
rm -rf "$out"
mkdir -p "$out"

# The template (writes the Sheet point array: the wall of each boundary point's atom).
"$medial" template "$data/template_myocardium.nii.gz" --out "$out/template.vtk" \
  --sheet "$out/sheet.vtk" --quiet > "$out/template.json"

# The cycle: frame k of 3 at s = k/3 of end-systole. Its walls are thickened by 1 + 0.575 s
# about the medial sheet (frameK/thickening.csv: the factor applied per atom, lower where the
# wall as asked would cross itself), its affine part scales by 1 - 0.1 s about the template's
# centre (the mean of its boundary points).
centre=$(python3 "$here/walls.py" centre "$out/template.vtk")
for k in 1 2 3; do
  s=$(python3 -c "print($k / 3)")
  python3 "$here/walls.py" affine "$centre" "$(python3 -c "print(1 - 0.1 * $s)")" \
    > "$out/frame$k.affine.txt"
  "$medial" synth --from "$out/template.vtk" --out "$out/frame$k" --spacing 1 --bend 0 \
    --twist "$(python3 -c "print(12 * $s)")" --affine "$out/frame$k.affine.txt" \
    --thicken "$(python3 -c "print(1 + 0.575 * $s)")" --quiet > "$out/frame$k.json"
  "$medial" fit --template "$out/template.vtk" --image "$out/frame$k/target.nii.gz" \
    --out "$out/fit$k" --quiet > "$out/fit$k.json"
done

# Per wall and frame: the atoms' thickness ratio to the template's against the planted one
# (the factor applied times 1 - 0.1 s; walls.csv, a table on stdout, walls.svg), and the fitted
# templates as a series for ParaView (cycle.vtk.series).
python3 "$here/walls.py" walls "$out" 3 | tee "$out/walls.md"
