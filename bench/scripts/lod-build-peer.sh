#!/usr/bin/env bash
# The level-of-detail build against its peer, in the same run (issue 51's build target):
# meshoptimizer's clusterlod (`meshopt::clod_build`, the `clusterlod` bench binary: in core,
# one thread, clusters of 128 triangles) and `tessera encode --lod` (out of core, BFT streams
# written) on one thread and on every core, alternated RUNS times on the subdivided dragon of
# at least MIN_TRIANGLES (default 13M: 2 levels, 13.9M triangles), generated into a temporary
# folder. Prints each run's wall time, input triangles/s and peak memory (/usr/bin/time), and
# the medians' ratios: this machine's speed drifts by 2x from session to session, so only
# the ratios in one run compare. Then the bytes a triangle of the --lod file and of the
# peer's hierarchy stored as meshopt-coded clusters (`clusterlod --bytes`).
#   usage: bench/scripts/lod-build-peer.sh [MIN_TRIANGLES] [RUNS] [TMPDIR]
set -euo pipefail
cd "$(dirname "$0")/../.."
MIN="${1:-13M}"
RUNS="${2:-2}"
DIR="${3:-${TMPDIR:-/tmp}/tessera-lod-peer}"
mkdir -p "$DIR"
cargo build --release -q -p tessera -p tessera-bench --bin tessera --bin subdivide --bin clusterlod
T=target/release
PLY="$DIR/dragon-$MIN.ply"
if [ ! -s "$PLY" ]; then
  $T/subdivide ../shared/meshes/stanford/dragon_vrip.ply.gz --min-triangles "$MIN" -o "$PLY"
fi
# The input's triangles, from the PLY header the generator wrote.
TRIS=$(python3 -c "
import sys
with open(sys.argv[1], 'rb') as f:
    for line in f:
        if line.startswith(b'element face'):
            print(int(line.split()[2])); break
" "$PLY")
: > "$DIR/runs"
one() { # name, command...
  local name="$1"; shift
  /usr/bin/time -f "%e %M" "$@" > "$DIR/out" 2> "$DIR/time" || { cat "$DIR/out" "$DIR/time"; exit 1; }
  read -r wall kb < <(tail -1 "$DIR/time")
  echo "$name $wall $kb" >> "$DIR/runs"
  python3 -c "print(f'$name: {$wall:.1f} s, {$TRIS / $wall / 1e6:.3f}M triangles/s, {$kb / 1024:.0f} MB peak')"
}
for _ in $(seq "$RUNS"); do
  one clusterlod $T/clusterlod "$PLY"
  one "tessera-1-thread" env RAYON_NUM_THREADS=1 $T/tessera encode "$PLY" --lod -o "$DIR/lod.bft" --temp-dir "$DIR"
  one "tessera-$(nproc)-threads" $T/tessera encode "$PLY" --lod -o "$DIR/lod.bft" --temp-dir "$DIR"
done
python3 - "$DIR/runs" <<'EOF'
import statistics, sys
runs = {}
for line in open(sys.argv[1]):
    name, wall, _ = line.split()
    runs.setdefault(name, []).append(float(wall))
med = {k: statistics.median(v) for k, v in runs.items()}
peer = med.pop("clusterlod")
for name, wall in med.items():
    print(f"median {name}: {wall:.1f} s against clusterlod's {peer:.1f} s on one thread: {peer / wall:.2f}x its speed")
EOF
# Bytes: the --lod file against the peer's hierarchy stored as meshopt-coded clusters.
python3 -c "import os; b = os.path.getsize('$DIR/lod.bft'); print(f'encode --lod: {b} bytes, {b / $TRIS:.2f} a triangle')"
$T/clusterlod "$PLY" --bytes | tail -1
rm -f "$DIR/lod.bft"
