#!/usr/bin/env bash
# Runs one fuzz target, niced, on its seeds (seeds/TARGET, read-only) and its growing corpus
# (corpus/TARGET, git-ignored), with the memory and input-size limits chosen for it. Crashes
# land in artifacts/TARGET/. Extra arguments go to libFuzzer, e.g.
#   fuzz/run.sh npy -runs=10000000
#   fuzz/run.sh vtk_ascii -max_total_time=600
# Needs cargo-fuzz (`cargo install cargo-fuzz`); RUSTC_BOOTSTRAP lets the stable toolchain
# take the nightly-only flags it passes.
set -euo pipefail
cd "$(dirname "$0")"
target=${1:?usage: fuzz/run.sh TARGET [LIBFUZZER_ARGS...]}
shift
case "$target" in
  vtk_ascii | vtk_binary) max_len=65536 ;;
  obj) max_len=16384 ;;
  gltf | glb | nifti | nifti_gz | exr | config) max_len=8192 ;;
  npy) max_len=2048 ;;
  *) echo "unknown target $target" >&2; exit 2 ;;
esac
mkdir -p "corpus/$target"
RUSTC_BOOTSTRAP=1 exec nice -n 19 cargo fuzz run --sanitizer none --debug-assertions "$target" \
  "corpus/$target" "seeds/$target" -- \
  -rss_limit_mb=2048 -malloc_limit_mb=2048 -max_len="$max_len" -timeout=10 -print_final_stats=1 "$@"
