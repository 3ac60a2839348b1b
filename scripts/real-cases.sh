#!/usr/bin/env bash
# The real-case table (issue 29): every real template/target pair of ../shared/data through the
# automatic fit of the release binary, as a new user would run it, one markdown row per case.
#
#   bash scripts/real-cases.sh [DATA] [OUT] [--skip-slow]
#
# DATA: the shared data folder (default ../shared/data beside the repository root); OUT: the
# results (default target/real-cases under the repository root). Relative paths given on the
# command line are taken from the current folder. Each case fits into OUT/<case>/, its commands
# and their stderr go to OUT/<case>.log, and OUT/table.md holds the table (also printed at the
# end). A case that fails (an inflation error, a fit ending with exit 1, 3 or 4) is a row with its
# exit code and status; the script goes on with the next one. --skip-slow leaves out the KeOps
# hippocampus (6,611 points, minutes). The figures are read from each fit's summary.json.
set -euo pipefail

usage() {
  sed -n '2,13p' "$0" | sed 's/^# \{0,1\}//'
}

root="$(cd "$(dirname "$0")/.." && pwd)"
skip_slow=0
positional=()
for arg in "$@"; do
  case "$arg" in
    --skip-slow) skip_slow=1 ;;
    -h | --help) usage; exit 0 ;;
    -*) echo "real-cases.sh: unknown option '$arg'" >&2; usage >&2; exit 2 ;;
    *) positional+=("$arg") ;;
  esac
done
if [ "${#positional[@]}" -gt 2 ]; then
  echo "real-cases.sh: at most two paths (DATA, OUT)" >&2
  exit 2
fi
data="${positional[0]:-$root/../shared/data}"
out="${positional[1]:-$root/target/real-cases}"
# shellcheck source=scripts/cases-lib.sh
source "$root/scripts/cases-lib.sh"
absolute_folders real-cases.sh cmrep
build_medial

# Each case sets `summary` (the fit's summary.json) and `command` (the fit as a user types it)
# before running; it returns the exit code of its first failing step.

case_anterior_leaflet() {
  # docs/fit.md: cmrep's fitted sheet inflated by `medial inflate` (no subdivision).
  summary="$dir/fit/summary.json"
  command="medial inflate leaflets/anterior_def1_A.vtk; medial fit --image leaflets/target_anterior.nii.gz"
  run inflate "$dir/inflate.json" "$medial" inflate "$data/cmrep/leaflets/anterior_def1_A.vtk" \
    --out "$dir/template.vtk" || return $?
  run fit "$dir/fit.json" "$medial" fit --template "$dir/template.vtk" \
    --image "$data/cmrep/leaflets/target_anterior.nii.gz" --out "$dir/fit" || return $?
}

case_caudate() {
  summary="$dir/fit/summary.json"
  command="medial inflate real/caudate_pde_model.vtk; medial fit --image real/caudate_target.nii.gz"
  run inflate "$dir/inflate.json" "$medial" inflate "$data/cmrep/real/caudate_pde_model.vtk" \
    --out "$dir/template.vtk" || return $?
  run fit "$dir/fit.json" "$medial" fit --template "$dir/template.vtk" \
    --image "$data/cmrep/real/caudate_target.nii.gz" --out "$dir/fit" || return $?
}

case_hippocampus_t002() {
  summary="$dir/fit/summary.json"
  command="medial inflate real/t002_hipp-prob_template.vtk; medial fit --image real/t002_hipp-prob_target.nii.gz"
  run inflate "$dir/inflate.json" "$medial" inflate "$data/cmrep/real/t002_hipp-prob_template.vtk" \
    --out "$dir/template.vtk" || return $?
  run fit "$dir/fit.json" "$medial" fit --template "$dir/template.vtk" \
    --image "$data/cmrep/real/t002_hipp-prob_target.nii.gz" --out "$dir/fit" || return $?
}

case_placenta() {
  summary="$dir/fit/summary.json"
  command="medial inflate --subdivide 1 placenta_template_anterioralign3.vtk; medial fit --surface placenta_template_def_to_target.vtk"
  run inflate "$dir/inflate.json" "$medial" inflate --subdivide 1 \
    "$data/cmrep/placenta_template_anterioralign3.vtk" --out "$dir/template.vtk" || return $?
  run fit "$dir/fit.json" "$medial" fit --template "$dir/template.vtk" \
    --surface "$data/cmrep/placenta_template_def_to_target.vtk" --out "$dir/fit" || return $?
}

case_cap_lv() {
  # The steps of examples/lv/run.sh (walls, ED template, ES mask, fit), with the same commands
  # and flags: that script writes only into examples/lv/out, so they are repeated here into
  # OUT/cap_lv. Keep the two in step.
  summary="$dir/es_fit/summary.json"
  command="examples/lv/run.sh: medial template ed_wall.vtk; medial rasterize es_wall.vtk --spacing 1; medial fit --image es_wall.nii.gz"
  run build-lv "$dir/build.txt" cargo build --release -q --example lv \
    --manifest-path "$root/Cargo.toml" || return $?
  local lv="$target_dir/release/examples/lv"
  run walls "$dir/walls.txt" "$lv" walls "$data/cap_lv" "$dir" || return $?
  run template "$dir/ed_template_figures.json" "$medial" template "$dir/ed_wall.vtk" \
    --out "$dir/ed_template.vtk" --sheet "$dir/ed_sheet.vtk" --work "$dir/ed_template_fit" \
    --quiet || return $?
  run rasterize "$dir/rasterize.txt" "$medial" rasterize "$dir/es_wall.vtk" \
    --out "$dir/es_wall.nii.gz" --spacing 1.0 || return $?
  run fit "$dir/es_fit_figures.json" "$medial" fit --template "$dir/ed_template.vtk" \
    --image "$dir/es_wall.nii.gz" --out "$dir/es_fit" --quiet || return $?
}

case_keops_hippocampus() {
  # A plain mesh (no MedialIndex): docs/fit.md's automatic fit of it, by --target.
  summary="$dir/fit/summary.json"
  command="medial fit --template keops/hippos_source.vtk --target keops/hippos_target.vtk"
  run fit "$dir/fit.json" "$medial" fit --template "$data/keops/hippos_source.vtk" \
    --target "$data/keops/hippos_target.vtk" --out "$dir/fit" || return $?
}

cases=(anterior_leaflet caudate hippocampus_t002 placenta cap_lv)
if [ "$skip_slow" -eq 0 ]; then
  cases+=(keops_hippocampus)
fi

# row CASE: one markdown row from the case's summary.json (or from its log when there is none).
row() {
  python3 -c '
import json, os, sys
case, rc, step, summary, log, command, wall = sys.argv[1:8]
def cell(s):
    return str(s).replace("|", "\\|").replace("\n", " ")
def num(x):
    if x is None:
        return "—"
    return format(x, ".2f" if abs(x) >= 0.1 else ".3f" if abs(x) >= 0.01 else ".4f")
if os.path.isfile(summary):
    d = json.load(open(summary))
    f = d.get("final", {})
    over = d.get("over_time") or {}
    status = d.get("status", "?")
    if f.get("voxel_dice") is not None:
        fit = "voxel Dice " + format(f["voxel_dice"], ".3f")
    elif f.get("surface_distance") is not None:
        fit = format(f["surface_distance"], ".3f") + " mm to the surface"
    elif f.get("mean_distance") is not None:
        fit = format(f["mean_distance"], ".3f") + " mm to the points"
    else:
        fit = "—"
    def medial(key):
        a, b = f.get(key), over.get(key)
        if a is None:
            return "— (no constraints)" if key.endswith("deg") else "—"
        return num(a) + ("" if b is None else " (" + num(b) + ")")
    angle = medial("max_spoke_normal_deg")
    mismatch = medial("max_spoke_mismatch_pct")
    k = str(d.get("landmarks", "—"))
    evals = format(d.get("evaluations", 0), ",")
    secs = format(d.get("seconds", 0), ".1f")
    note = ""
    if rc != "0":
        note = "see " + os.path.basename(log)
else:
    status = "error (" + step + ")" if step else "error"
    fit = angle = mismatch = k = evals = secs = "—"
    note = ""
    if os.path.isfile(log):
        errs = [l.strip() for l in open(log, errors="replace") if l.lower().startswith("error")]
        if errs:
            note = errs[-1][:240]
print("| " + " | ".join(cell(c) for c in [case, "`" + command + "`", k, rc, status, fit, angle,
      mismatch, evals, secs + " / " + wall, note]) + " |")
' "$@"
}

rows=()
for c in "${cases[@]}"; do
  dir="$out/$c"
  log="$out/$c.log"
  failed_step=""
  summary=""
  command=""
  rm -rf "$dir"
  mkdir -p "$dir"
  : >"$log"
  echo "real-cases.sh: $c ..." >&2
  start="$(date +%s)"
  rc=0
  "case_$c" || rc=$?
  wall="$(($(date +%s) - start))"
  echo "real-cases.sh: $c exit $rc after $wall s" >&2
  rows+=("$(row "$c" "$rc" "$failed_step" "$summary" "$log" "$command" "$wall")")
done

commit="$(commit_of_root)"
{
  echo "Made by \`bash scripts/real-cases.sh\` on $(date -u '+%Y-%m-%d %H:%M UTC'), $("$medial" --version), commit $commit,"
  echo "$(nproc) cores, load average at the end $(cut -d' ' -f1-3 /proc/loadavg 2>/dev/null || echo unknown)."
  echo "Data: \`$data\`. Angle and mismatch: at the end of the fit (worst over its time points)."
  echo
  echo "| case | commands (paths under the data folder) | landmarks | exit | status | fit | max spoke–normal (°) | max mismatch (%) | evaluations | seconds (fit / case) | note |"
  echo "|---|---|---|---|---|---|---|---|---|---|---|"
  printf '%s\n' "${rows[@]}"
} >"$out/table.md"
echo
cat "$out/table.md"
