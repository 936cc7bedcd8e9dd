#!/usr/bin/env bash
# Builds a model with `tessera pm build --spill-dir` in memory cgroups of the given limits (the
# build's data larger than memory, issue 16 item 2), after a build without a limit, and
# prints per build its wall time, peak resident memory, its peak anonymous memory (`RssAnon`
# sampled every half second: what stays in memory outside the spill files, about 100 MB
# whatever the model) and whether the file is the same bytes. Not run by CI: it needs root and a writable cgroup memory controller (v2 or v1).
# Usage: bench/scripts/pm-build-capped.sh MODEL.ply SPILL_DIR LIMIT... (LIMIT as the kernel takes
# it: 900M, 3500M, ...)
#   e.g. bench/scripts/pm-build-capped.sh /tmp/pm13/d.ply /tmp/spill 900M 700M 550M
# The models come from bench/scripts/pm-scale.sh (the dragon at 13.9M, the armadillo at 102M).
set -euo pipefail
cd "$(dirname "$0")/../.."
MODEL="$1"
SPILL="$2"
shift 2
cargo build --release -q -p tessera --bin tessera
T="$(realpath "${CARGO_TARGET_DIR:-target}")/release/tessera"
mkdir -p "$SPILL"
OUT="$SPILL/capped-reference.dpm"
show() {
  grep -E "built in|kept up to|Maximum resident|Elapsed" "$1" | sed 's/^[[:space:]]*/   /'
}
# The most anonymous memory (MB) of the child of process $1 (the build under /usr/bin/time)
# while $1 runs.
anon_peak() {
  local max=0 child a
  while kill -0 "$1" 2>/dev/null; do
    child="$(pgrep -P "$1" | head -1 || true)"
    if [ -n "$child" ]; then
      a="$(awk '/^RssAnon/ {print $2}' "/proc/$child/status" 2>/dev/null || true)"
      if [ -n "$a" ] && [ "$a" -gt "$max" ]; then max="$a"; fi
    fi
    sleep 0.5
  done
  echo $(( max / 1024 ))
}

echo "== without a limit"
/usr/bin/time -v "$T" pm build "$MODEL" -o "$OUT" --node-kb 64 > "$SPILL/capped.log" 2>&1
show "$SPILL/capped.log"

# A cgroup with memory limit $1 named $2; echoes its folder and the files to read.
make_cgroup() {
  if [ -f /sys/fs/cgroup/cgroup.controllers ]; then
    local cg="/sys/fs/cgroup/tessera-$2"
    mkdir -p "$cg"
    echo "$1" > "$cg/memory.max"
    echo "$cg memory.peak"
  else
    local cg="/sys/fs/cgroup/memory/tessera-$2"
    mkdir -p "$cg"
    echo "$1" > "$cg/memory.limit_in_bytes"
    echo "$cg memory.max_usage_in_bytes"
  fi
}

for LIMIT in "$@"; do
  echo "== in a cgroup of $LIMIT, --spill-dir $SPILL"
  read -r CG PEAK < <(make_cgroup "$LIMIT" "$LIMIT")
  X="$SPILL/capped-$LIMIT.dpm"
  set +e
  bash -c "echo \$\$ > $CG/cgroup.procs; exec /usr/bin/time -v $T pm build $MODEL -o $X --node-kb 64 --spill-dir $SPILL" \
    > "$SPILL/capped.log" 2>&1 &
  BUILD=$!
  ANON="$(anon_peak "$BUILD")"
  wait "$BUILD"
  rc=$?
  set -e
  show "$SPILL/capped.log"
  echo "   exit $rc, cgroup peak $(( $(cat "$CG/$PEAK" 2>/dev/null || echo 0) / 1048576 )) MiB, anonymous memory at most $ANON MB"
  if cmp -s "$OUT" "$X"; then echo "   the same bytes"; else echo "   DIFFERENT bytes"; fi
  rm -f "$X"
  rmdir "$CG" 2>/dev/null || true
done
rm -f "$OUT"
