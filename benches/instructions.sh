#!/usr/bin/env bash
# Instruction counts of the workloads of benches/instructions.rs (one evaluation at k = 503,
# one Dice attachment), counted by callgrind, against benches/instructions.baseline. Prints
# each count, the baseline and the change; fails only when a count rose by more than 10 %.
# `benches/instructions.sh --update` writes the counts to the baseline instead.
#
# Counts are of one rayon thread (idle workers spin for a varying number of instructions) and
# of the code path valgrind's CPU offers (AVX2 + FMA: valgrind has no AVX-512), so they are
# stable from run to run on a loaded machine, unlike times. A script rather than the
# iai-callgrind / gungraun crates: those need their runner installed with `cargo install`,
# a build of its own longer than CI's budget for this step.
set -euo pipefail
cd "$(dirname "$0")/.."
baseline=benches/instructions.baseline
cases=(evaluation dice)
max_rise_percent=10

command -v valgrind >/dev/null || { echo "valgrind is not installed" >&2; exit 1; }
binary=$(cargo bench --locked --bench instructions --no-run --message-format=json 2>/dev/null |
  grep -o '"executable":"[^"]*"' | tail -n 1 | cut -d '"' -f 4)
[[ -x "$binary" ]] || { echo "the instructions bench did not build" >&2; exit 1; }

out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
declare -A counts
for case in "${cases[@]}"; do
  RAYON_NUM_THREADS=1 valgrind --tool=callgrind --collect-atstart=no \
    --toggle-collect='*instructions*measured*' --callgrind-out-file="$out/$case" \
    "$binary" "$case" >"$out/$case.log" 2>&1 || { cat "$out/$case.log" >&2; exit 1; }
  counts[$case]=$(awk '/^(summary|totals):/ { n = $2 } END { print n }' "$out/$case")
  # An arithmetic intrinsic that runs as a function of its own was not inlined into the code compiled for
  # its instruction set: a codegen accident that costs several times the instructions (once
  # the exponential's closures were not inlined into the AVX2 tile body: 4.5x).
  # (Inlined intrinsics leave no function of their own in the profile's `fn=` / `cfn=` names;
  # the feature detection's `_xgetbv` and `__cpuid` are meant to be calls.)
  if grep -E '^c?fn=.*core_arch::x86(_64)?::(avx|fma|sse)' "$out/$case" >&2; then
    echo "$case: SIMD intrinsics called out of line (the functions above)" >&2
    exit 1
  fi
  [[ "${counts[$case]}" =~ ^[0-9]+$ && "${counts[$case]}" -gt 0 ]] ||
    { echo "no instructions counted for $case" >&2; exit 1; }
done

if [[ "${1:-}" == "--update" ]]; then
  {
    echo "# Instructions counted by benches/instructions.sh (callgrind, one thread). Update with"
    echo "# \`benches/instructions.sh --update\` when a change is meant to cost more."
    for case in "${cases[@]}"; do echo "$case ${counts[$case]}"; done
  } >"$baseline"
  cat "$baseline"
  exit 0
fi

status=0
for case in "${cases[@]}"; do
  base=$(awk -v c="$case" '$1 == c { print $2 }' "$baseline")
  [[ -n "$base" ]] || { echo "$case: not in $baseline" >&2; status=1; continue; }
  now=${counts[$case]}
  change=$(awk -v n="$now" -v b="$base" 'BEGIN { printf "%+.2f", 100 * (n - b) / b }')
  echo "$case: $now instructions (baseline $base, $change %)"
  if awk -v n="$now" -v b="$base" -v m="$max_rise_percent" 'BEGIN { exit !(n > b * (1 + m / 100)) }'; then
    echo "$case: more than $max_rise_percent % above the baseline" >&2
    status=1
  fi
done
exit "$status"
