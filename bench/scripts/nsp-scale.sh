#!/usr/bin/env bash
# The nSP-tree store's out-of-core build at two scales (issue 15), not run by CI: subdivides
# armadillo_100k by LOW and HIGH levels (default 2 and 4: 1.6M and 25.6M triangles) into a
# temporary folder and builds each with `tessera nsp build` under /usr/bin/time -v, for each
# geometry advance given, then prints time, triangles/s, peak memory and the ratio of the
# peaks (issue 15 asks at most 300 MB, and at most 1.3x from about 2M to 20M triangles).
# Usage: bench/scripts/nsp-scale.sh [ADVANCES] [LOW] [HIGH] [TMPDIR]   (e.g. bench/scripts/nsp-scale.sh "0 2")
set -euo pipefail
cd "$(dirname "$0")/../.."
ADVANCES="${1:-0 2}"
LOW="${2:-2}"
HIGH="${3:-4}"
DIR="${4:-${TMPDIR:-/tmp}/tessera-nsp-scale}"
mkdir -p "$DIR"
cargo build --release -q -p tessera -p tessera-bench --bin tessera --bin subdivide
BIN="${CARGO_TARGET_DIR:-target}/release"
T="$BIN/tessera"
MESH=../shared/meshes/stanford/armadillo_100k.obj.gz
for L in "$LOW" "$HIGH"; do
  [ -s "$DIR/arm-$L.ply" ] || "$BIN/subdivide" "$MESH" --levels "$L" -o "$DIR/arm-$L.ply" > /dev/null
done
for M in $ADVANCES; do
  peaks=()
  for L in "$LOW" "$HIGH"; do
    /usr/bin/time -v $T nsp build "$DIR/arm-$L.ply" -o "$DIR/arm-$L.nsp" --advance "$M" --temp-dir "$DIR" \
      > "$DIR/build-$L-$M.txt" 2> "$DIR/build-$L-$M.time"
    tris=$(grep -oE "\([0-9]+ in the input" "$DIR/build-$L-$M.txt" | grep -oE "[0-9]+")
    wall=$(grep "Elapsed" "$DIR/build-$L-$M.time" | awk '{print $NF}' | awk -F: '{ if (NF == 3) print $1*3600+$2*60+$3; else print $1*60+$2 }')
    kb=$(grep "Maximum resident" "$DIR/build-$L-$M.time" | awk '{print $6}')
    peaks+=("$kb")
    awk -v m="$M" -v l="$L" -v t="$tris" -v w="$wall" -v kb="$kb" -v b="$(stat -c %s "$DIR/arm-$L.nsp")" \
      'BEGIN { printf "--advance %s, %s levels: %d triangles, %.1f s, %.0fk triangles/s, peak %.0f MB, %d bytes\n", m, l, t, w, t / w / 1000, kb / 1024, b }'
  done
  awk -v m="$M" -v a="${peaks[0]}" -v b="${peaks[1]}" 'BEGIN { printf "--advance %s: peak memory ratio %.2f\n", m, b / a }'
done
