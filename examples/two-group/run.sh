#!/usr/bin/env bash
# A two-group study end to end (issue 31): 8 "patients" with a regional thickening of known
# size and place and 8 "controls" without, each subject the toy template under its own smooth
# warp (medial synth --from), all fitted by one medial batch, thickness tested at every atom by
# medial stats, the significant atoms compared with the truth (Dice); and a null version of the
# same study (the patients' warps without the thickening) that must find nothing.
#   bash examples/two-group/run.sh        # from anywhere; writes only examples/two-group/out/
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
here="$root/examples/two-group"
out="$here/out"
target="${CARGO_TARGET_DIR:-$root/target}"
(cd "$root" && cargo build --release -q -p medial-cli)
medial="$target/release/medial"
template="$root/examples/toy/template.vtk"

# The planted effect: spokes scaled by $factor at atom $atom (the middle of one of the toy's three
# sheets), by 1 from $radius mm on, a raised cosine between (thickening.csv: the truth per atom);
# FACTOR=… RADIUS=… bash run.sh tries another.
factor=${FACTOR:-1.2}
atom=74
radius=${RADIUS:-10}
permutations=4999
start=$(date +%s.%N)
rm -rf "$out"
mkdir -p "$out/cases"

# One subject: NAME BEND TWIST ROTATE SEED [thickened]; its segmentation is cases/NAME/target.nii.gz.
synth() {
  local name=$1 bend=$2 twist=$3 rotate=$4 seed=$5 thick=${6:-}
  local extra=()
  [ -n "$thick" ] && extra=(--thicken-region "$factor" --region-atom "$atom" --region-radius "$radius")
  "$medial" synth --from "$template" --bend "$bend" --twist "$twist" --rotate "$rotate" \
    --seed "$seed" "${extra[@]}" --out "$out/cases/$name" --quiet >/dev/null
}

echo "subject,image" >"$out/subjects.csv"
echo "subject,group" >"$out/design.csv"
echo "subject,group" >"$out/design_null.csv"
# k  control: bend twist rotate seed | patient: bend twist rotate seed
while read -r k cb ct cr cs pb pt pr ps; do
  synth "c$k" "$cb" "$ct" "$cr" "$cs"
  synth "p$k" "$pb" "$pt" "$pr" "$ps" thickened
  synth "n$k" "$pb" "$pt" "$pr" "$ps"          # the patient's warp, not thickened
  for s in "c$k" "p$k" "n$k"; do echo "$s,cases/$s/target.nii.gz" >>"$out/subjects.csv"; done
  echo "c$k,control" >>"$out/design.csv"
  echo "c$k,control" >>"$out/design_null.csv"
done <<LIST
1 -12  6 3 11   10 -6 4 21
2   8 -8 5 12  -14  8 2 22
3  15  4 2 13    6 10 5 23
4  -6 -4 6 14  -10 -8 3 24
5   4 10 4 15   14  2 6 25
6 -15 -2 2 16   -4 -2 4 26
7  10  8 5 17   12 -10 2 27
8   0 -10 3 18   -8  6 5 28
LIST
for k in 1 2 3 4 5 6 7 8; do
  echo "p$k,patient" >>"$out/design.csv"
  echo "n$k,patient" >>"$out/design_null.csv"
done
made=$(date +%s.%N)

# Every subject fitted from the toy template (automatic settings); a failed fit is recorded and
# left out of the tests by medial stats.
"$medial" batch "$template" "$out/subjects.csv" --out "$out/batch" --quiet >"$out/batch.json" \
  2>"$out/batch.log" ||
  echo "medial batch: some fits failed (see $out/batch/cohort.csv)" >&2
fitted=$(date +%s.%N)

for study in stats stats_null; do
  design="$out/design.csv"
  [ "$study" = stats_null ] && design="$out/design_null.csv"
  "$medial" stats "$out/batch" --design "$design" --contrast 'group[patient] - group[control]' \
    --array thickness --permutations "$permutations" --seed 1 --tfce --out "$out/$study" \
    --quiet >/dev/null 2>"$out/$study.log"
done
tested=$(date +%s.%N)

python3 "$here/dice.py" "$out" "$factor" "$start" "$made" "$fitted" "$tested" | tee "$out/summary.txt"
exit "${PIPESTATUS[0]}"
