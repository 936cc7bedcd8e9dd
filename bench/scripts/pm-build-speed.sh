#!/usr/bin/env bash
# Build speed of progressive meshes (issue 16's target: 200k operations/s on the dragon),
# measured against a baseline revision in the same run, since this machine's speed drifts
# from day to day (the same code measured 78k and 213k operations/s two days apart): builds
# `tessera` at REV (default main) and at the working tree, then runs `tessera pm build MESH`
# with each in turn, RUNS times, and prints every run's simplifying and compressing times,
# operations/s and peak memory (/usr/bin/time), the medians and the ratio of the medians. The
# two files must be identical (a speed-up must not change the bytes; a format change shows
# as "files differ").
#   usage: bench/scripts/pm-build-speed.sh [REV] [RUNS]     (BASE_BIN=path skips building REV;
#          MESH=file, default the dragon; BUILD_ARGS="--node-kb 64" for an out-of-core build)
set -euo pipefail
cd "$(dirname "$0")/../.."
rev="${1:-main}"
runs="${2:-6}"
mesh="${MESH:-../shared/meshes/stanford/dragon_vrip.ply.gz}"
work="$(mktemp -d /tmp/tessera-speed.XXXXXX)"
trap 'git worktree remove --force "$work/src" >/dev/null 2>&1 || true; rm -rf "$work"' EXIT
target="${CARGO_TARGET_DIR:-target}"

if [ -z "${BASE_BIN:-}" ]; then
  git worktree add -q --detach "$work/src" "$rev"
  echo "pm-build-speed: building $rev"
  CARGO_TARGET_DIR="$target" cargo build -q --release -p tessera --manifest-path "$work/src/Cargo.toml"
  cp "$target/release/tessera" "$work/base"
  BASE_BIN="$work/base"
fi
echo "pm-build-speed: building the working tree"
cargo build -q --release -p tessera
cp "$target/release/tessera" "$work/new"

for i in $(seq "$runs"); do
  for which in base new; do
    bin="$work/new"
    [ "$which" = base ] && bin="$BASE_BIN"
    # shellcheck disable=SC2086
    /usr/bin/time -f "%M" "$bin" pm build "$mesh" -o "$work/$which.dpm" ${BUILD_ARGS:-} > "$work/out" 2> "$work/time"
    echo "$which $(grep -o 'built in [0-9]* ms + compressed in [0-9]* ms ([0-9]* ops/s)' "$work/out") $(tail -1 "$work/time")" \
      | tee -a "$work/runs"
  done
done
cmp -s "$work/base.dpm" "$work/new.dpm" && echo "pm-build-speed: the files are identical" \
  || echo "pm-build-speed: files differ"
python3 - "$work/runs" "$rev" <<'EOF'
import re, statistics, sys
runs = {"base": [], "new": []}
for line in open(sys.argv[1]):
    m = re.match(r"(\w+) built in (\d+) ms \+ compressed in (\d+) ms \((\d+) ops/s\) (\d+)", line)
    runs[m[1]].append(tuple(int(x) for x in m.groups()[1:]))
med = {k: [statistics.median(r[i] for r in v) for i in range(4)] for k, v in runs.items()}
for k, name in (("base", sys.argv[2]), ("new", "working tree")):
    b, c, o, kb = med[k]
    print(f"{name:>14}: median simplify {b:.0f} ms, compress {c:.0f} ms, {o / 1e3:.1f}k ops/s, peak {kb / 1024:.0f} MB"
          f" (ops/s {min(r[2] for r in runs[k]) / 1e3:.1f}k-{max(r[2] for r in runs[k]) / 1e3:.1f}k)")
print(f"ratio of medians (working tree / {sys.argv[2]}): {med['new'][2] / med['base'][2]:.2f}x ops/s, "
      f"compress {med['base'][1] / med['new'][1]:.2f}x faster, simplify {med['base'][0] / med['new'][0]:.2f}x faster")
EOF
