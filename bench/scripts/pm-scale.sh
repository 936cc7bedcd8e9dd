#!/usr/bin/env bash
# The scale run of out-of-core progressive meshes (issue 16), not run by CI: generates a model
# of at least MIN_TRIANGLES (default 13M; K, M, G are powers of 1024, so write 100000000 for
# a hundred million) from $MESH (default the dragon) by subdivision into a temporary
# folder, builds it out of core in 64 kB nodes (time and peak memory, /usr/bin/time -v), and
# renders an orbit with one worker at 1920x1080 under each GPU budget, printing per frame the
# adapted triangles, the worker's graphics memory (node pool, tables and adapted mesh: within
# the budget), the node bytes loaded, the resident, required and slot counts of nodes, and the
# factor on --error-px the budget held the mesh to.
# Usage: [MESH=FILE] bench/scripts/pm-scale.sh [MIN_TRIANGLES] [TMPDIR] [BUDGETS_MB...]
#   e.g. bench/scripts/pm-scale.sh 13M /tmp/tessera-pm 16 128
#   MESH=../shared/meshes/stanford/armadillo_100k.obj.gz ERROR_PX=2 bench/scripts/pm-scale.sh 100000000 /tmp/pm100 512
# ERROR_PX sets render's --error-px (default its own, 0.5). Where the budget, or lavapipe's
# 128 MiB per buffer (about 1.05M vertices), cannot hold the mesh at that error, the worker
# adapts to a larger one (the error scale column).
set -euo pipefail
cd "$(dirname "$0")/../.."
MIN="${1:-13M}"
DIR="${2:-${TMPDIR:-/tmp}/tessera-pm-scale}"
shift $(( $# < 2 ? $# : 2 ))
BUDGETS=("${@:-16 128}")
read -r -a BUDGETS <<< "${BUDGETS[*]}"
mkdir -p "$DIR"
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-/tmp/tessera-xdg}" OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
mkdir -p "$XDG_RUNTIME_DIR"
cargo build --release -q -p tessera -p tessera-bench --bin tessera --bin subdivide
BIN="${CARGO_TARGET_DIR:-target}/release"
T="$BIN/tessera"
MESH="${MESH:-../shared/meshes/stanford/dragon_vrip.ply.gz}"
NAME="$(basename "$MESH" | sed 's/[._].*//')-$MIN"
PLY="$DIR/$NAME.ply"
DPM="$DIR/$NAME.dpm"
peak() { grep -E "Maximum resident" "$1" | awk '{printf "%.0f MB", $6/1024}'; }

if [ ! -s "$PLY" ]; then
  "$BIN/subdivide" "$MESH" --min-triangles "$MIN" -o "$PLY"
fi
if [ ! -s "$DPM" ]; then
  echo "== pm build $PLY --node-kb 64"
  /usr/bin/time -v $T pm build "$PLY" -o "$DPM" --node-kb 64 2> "$DIR/build.time" | tee "$DIR/build.txt"
  echo "   peak memory $(peak "$DIR/build.time"), wall $(grep Elapsed "$DIR/build.time" | awk '{print $NF}')"
fi
$T pm stats "$DPM" | grep -E "bytes|nodes|operations"

for B in "${BUDGETS[@]}"; do
  echo "== render, 6 frames of an orbit, --gpu-budget-mb $B"
  /usr/bin/time -v mpirun --bind-to none --oversubscribe -np 2 $T render "$DPM" --size 1920x1080 --tiles 4x4 \
    --frames 6 --orbit --gpu-budget-mb "$B" ${ERROR_PX:+--error-px "$ERROR_PX"} --out "$DIR/b$B.png" --stats "$DIR/b$B.jsonl" 2> "$DIR/b$B.time" > /dev/null
  echo "   peak memory of a rank $(peak "$DIR/b$B.time")"
  python3 - "$DIR/b$B.jsonl" <<'EOF'
import json, sys
print("   frame  triangles  adapt ms  GPU MB  loaded kB  resident/required nodes  slots  error scale")
for l in open(sys.argv[1]):
    d = json.loads(l)
    if d.get("rank") != 1 or "pm" not in d:
        continue
    p = d["pm"]
    print(f"   {d['frame']:5d}  {d['tiles'][0]['triangles']:9d}  {d['adapt_ms']:8.0f}  {p['gpu_bytes'] / 2**20:6.1f}"
          f"  {p['loaded_bytes'] / 1024:9.0f}  {p['resident_nodes']:8d} / {p['required_nodes']:<8d}  {p['node_slots']:5d}"
          f"  {p['error_scale']:11.3f}")
EOF
done
