#!/bin/sh
# Writes the subjects of this cohort again: cmrep's t001 template under five known warps made by
# `medial synth --from` (a bend of the long axis across the wall, a twist about it, then a
# scaling about the centre), each rasterized at 0.5 mm into images/SUBJECT.nii.gz.
# Run from the repository's root: sh examples/cohort/make_subjects.sh [path/to/medial]
set -eu
medial=${1:-medial}
here=examples/cohort
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
mkdir -p "$here/images"
echo "subject,image" >"$here/subjects.csv"
# subject bend(°) twist(°) scale
while read -r subject bend twist scale; do
  printf '%s 0 0 0\n0 %s 0 0\n0 0 %s 0\n0 0 0 1\n' "$scale" "$scale" "$scale" >"$work/$subject.txt"
  "$medial" synth --from examples/t001/template.vtk --bend "$bend" --twist "$twist" \
    --affine "$work/$subject.txt" --spacing 0.5 --out "$work/$subject" >/dev/null
  cp "$work/$subject/target.nii.gz" "$here/images/$subject.nii.gz"
  echo "$subject,images/$subject.nii.gz" >>"$here/subjects.csv"
done <<LIST
s1 -30 0 0.94
s2 -15 10 0.97
s3 10 -10 1.00
s4 25 5 1.03
s5 40 15 1.06
LIST
