#!/usr/bin/env bash
# The paper's LV experiment on public data (../shared/data/cap_lv), end to end:
#   bash examples/lv/run.sh            # from the project root; results in examples/lv/out/
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
data="${LV_DATA:-$root/../shared/data/cap_lv}"
out="$root/examples/lv/out"
mkdir -p "$out"
target="${CARGO_TARGET_DIR:-$root/target}"
(cd "$root" && cargo build --release -q -p medial-cli && cargo build --release -q --example lv)
medial="$target/release/medial"
lv="$target/release/examples/lv"
"$lv" walls "$data" "$out"                                   # ed_wall.vtk, es_wall.vtk
"$medial" template "$out/ed_wall.vtk" --out "$out/ed_template.vtk" --sheet "$out/ed_sheet.vtk" \
  --work "$out/ed_template_fit" --quiet > "$out/ed_template_figures.json"
"$medial" rasterize "$out/es_wall.vtk" --out "$out/es_wall.nii.gz" --spacing 1.0 > /dev/null
"$medial" fit --template "$out/ed_template.vtk" --image "$out/es_wall.nii.gz" --out "$out/es_fit" \
  --quiet > "$out/es_fit_figures.json"
last="$(ls "$out"/es_fit/flow/medial_t*.vtk | sort | tail -1)"
"$lv" thickening "$out/ed_template.vtk" "$last" "$out/thickening.vtk" \
  | tee "$out/thickening.json"
