# Helpers shared by scripts/real-cases.sh and scripts/synthetic-cases.sh (sourced, not run).
# The sourcing script sets `root` (the repository root) first.

# absolute_folders SCRIPT NEEDED: refuses (exit 1) a data folder `$data` without the path NEEDED
# in it, then makes `data` and `out` (created if needed) absolute.
absolute_folders() {
  if [ ! -e "$data/$2" ]; then
    echo "$1: '$data' is not the shared data folder (no $2 in it)" >&2
    exit 1
  fi
  data="$(cd "$data" && pwd)"
  mkdir -p "$out"
  out="$(cd "$out" && pwd)"
}

# build_medial: builds the release binary and sets `target_dir` and `medial`.
build_medial() {
  cargo build --release -p medial-cli --manifest-path "$root/Cargo.toml"
  target_dir="${CARGO_TARGET_DIR:-$root/target}"
  case "$target_dir" in /*) ;; *) target_dir="$root/$target_dir" ;; esac
  medial="$target_dir/release/medial"
}

# run STEP STDOUT CMD...: runs CMD, its stdout to the file STDOUT, its stderr appended to the
# case's log `$log` (after the command line); on failure sets `failed_step` to STEP and returns
# CMD's exit code.
run() {
  local step="$1" stdout="$2" rc=0
  shift 2
  { printf '+'; printf ' %q' "$@"; printf '\n'; } >>"$log"
  "$@" >"$stdout" 2>>"$log" || rc=$?
  if [ "$rc" -ne 0 ]; then
    failed_step="$step"
    echo "exit $rc" >>"$log"
  fi
  return "$rc"
}

# commit_of_root: the short commit of the repository, and whether it has uncommitted changes.
commit_of_root() {
  local commit
  commit="$(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo "not a git checkout")"
  if [ "$commit" != "not a git checkout" ] && [ -n "$(git -C "$root" status --porcelain --untracked-files=no 2>/dev/null)" ]; then
    commit="$commit with uncommitted changes"
  fi
  echo "$commit"
}
