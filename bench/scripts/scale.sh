#!/usr/bin/env bash
# The scale benchmark of chunked models (issue 14), not run by CI: generates a model of at
# least MIN_TRIANGLES (default 200M) from the dragon by subdivision into a temporary folder,
# encodes it out of core, and renders it with workers that decode but do not rasterize
# (--decode-only), so that rank 0's sort, memory and traffic are measured apart from
# lavapipe:
#   1. encode: time, triangles/s, peak memory (/usr/bin/time -v);
#   2. a full view, 3 frames (each made: --no-frame-reuse): per frame rank 0's sort time and
#      resident memory, and the slowest worker's decode time;
#   3. a close-up that sees a few percent of the model, 3 frames;
#   4. a slow orbit (1 degree a frame, 6 frames): the bytes each frame sends against the first.
# With LOD=E in the environment the model is encoded with a level-of-detail hierarchy
# (encode --lod), every view draws the cut of --error-px E, the levels are listed, and a
# fly-through (32 frames from 4 model sizes away to the close-up's eye) is run too.
# Usage: [LOD=1] bench/scripts/scale.sh [MIN_TRIANGLES] [TMPDIR]   (e.g. bench/scripts/scale.sh 20M for a quick run)
set -euo pipefail
cd "$(dirname "$0")/../.."
MIN="${1:-200M}"
DIR="${2:-${TMPDIR:-/tmp}/tessera-scale}"
mkdir -p "$DIR"
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-/tmp/tessera-xdg}" OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
mkdir -p "$XDG_RUNTIME_DIR"
cargo build --release -q -p tessera -p tessera-bench --bin tessera --bin subdivide
T=target/release/tessera
PLY="$DIR/dragon-$MIN.ply"
BFT="$DIR/dragon-$MIN.bft"
MPI=(mpirun --bind-to none --oversubscribe -np 2)
ENCODE=()
CUT=()
if [ -n "${LOD:-}" ]; then
  BFT="$DIR/dragon-$MIN-lod.bft"
  ENCODE=(--lod)
  CUT=(--error-px "$LOD")
fi
peak() { grep -E "Maximum resident" "$1" | awk '{printf "%.0f MB", $6/1024}'; }

if [ ! -s "$PLY" ]; then
  target/release/subdivide ../shared/meshes/stanford/dragon_vrip.ply.gz --min-triangles "$MIN" -o "$PLY"
fi
echo "== encode $PLY ($(du -h "$PLY" | cut -f1))"
/usr/bin/time -v $T encode "$PLY" -o "$BFT" --temp-dir "$DIR" "${ENCODE[@]}" 2> "$DIR/encode.time" | tee "$DIR/encode.txt"
echo "   peak memory $(peak "$DIR/encode.time"), wall $(grep Elapsed "$DIR/encode.time" | awk '{print $NF}')"
if [ -n "${LOD:-}" ]; then
  $T stats "$BFT" | grep -E "bytes|level"
fi

# The master's stats lines: sort time, resident memory, chunk classes, bytes sent.
report() {
  python3 - "$1" <<'EOF'
import json, sys
lines = [json.loads(l) for l in open(sys.argv[1])]
m = [l for l in lines if l["rank"] == 0]
# The slowest worker's decoding by frame: a frame waits for the slower of rank 0's sort and
# the workers (0 where a worker had every stream from the frame before).
decode = {}
for l in lines:
    if l["rank"] != 0:
        decode[l["frame"]] = max(decode.get(l["frame"], 0), l.get("decode_ms", 0))
first = sum(t["bytes"] + t["normal_bytes"] for t in m[0]["tiles"])
for l in m:
    c = l["chunks"]
    sent = sum(t["bytes"] + t["normal_bytes"] for t in l["tiles"])
    drawn = sum(t["triangles"] for t in l["tiles"])
    cut = f'{c["not_in_cut"]} not in the cut / ' if c.get("not_in_cut") else ''
    print(f'   frame {l["frame"]}: sort {l["sort_ms"]:.0f} ms, '
          f'worker decode {decode.get(l["frame"], 0):.0f} ms, rank 0 {l["rss_mb"]:.0f} MB resident, '
          f'chunks {cut}{c["culled"]} culled / {c["verbatim"]} verbatim ({c["kept"]} kept) / {c["straddling"]} straddling '
          f'({c["straddling_triangles"]} triangles sorted, {c["built"]} built), {drawn} triangles in tiles, '
          f'sent {sent/1e6:.2f} MB ({sent/first:.3f} of the first frame)')
EOF
}

read -r LO HI < <($T stats "$BFT" --json | python3 -c 'import json,sys; s=json.load(sys.stdin); print(",".join(map(str,s["bbox_min"])), ",".join(map(str,s["bbox_max"])))')
echo "== full view, 1920x1080, 8x8 tiles, 3 frames"
"${MPI[@]}" $T render "$BFT" --size 1920x1080 --tiles 8x8 --frames 3 --no-frame-reuse --decode-only "${CUT[@]}" --out "$DIR/full.png" --stats "$DIR/full.jsonl" > /dev/null 2>&1
report "$DIR/full.jsonl"

# A close-up: from near the model's box, looking at a point of the surface side, narrow.
CLOSE=$(python3 -c "
lo=[float(v) for v in '$LO'.split(',')]; hi=[float(v) for v in '$HI'.split(',')]
c=[(a+b)/2 for a,b in zip(lo,hi)]; s=max(b-a for a,b in zip(lo,hi))
print(f'--target {c[0]},{c[1]},{c[2]} --eye {c[0]},{c[1]},{hi[2]+0.3*s} --fovy 12 --near {0.01*s} --far {4*s}')")
echo "== close-up ($CLOSE), 3 frames"
"${MPI[@]}" $T render "$BFT" --size 1920x1080 --tiles 8x8 --frames 3 --no-frame-reuse --decode-only "${CUT[@]}" $CLOSE --out "$DIR/close.png" --stats "$DIR/close.jsonl" > /dev/null 2>&1
report "$DIR/close.jsonl"

echo "== slow orbit, 1 degree a frame, 6 frames"
"${MPI[@]}" $T render "$BFT" --size 1920x1080 --tiles 8x8 --frames 6 --orbit --orbit-degrees 6 --decode-only "${CUT[@]}" --worker-cache-mb 2048 --out "$DIR/orbit.png" --stats "$DIR/orbit.jsonl" > /dev/null 2>&1
report "$DIR/orbit.jsonl"
if [ -n "${LOD:-}" ]; then
  # From four model sizes away to the close-up's eye (--zoom: the last frame's distance a
  # fraction of the first's), looking at the close-up's target: the cut refines as the eye
  # comes near.
  FLY=$(python3 -c "
lo=[float(v) for v in '$LO'.split(',')]; hi=[float(v) for v in '$HI'.split(',')]
c=[(a+b)/2 for a,b in zip(lo,hi)]; s=max(b-a for a,b in zip(lo,hi))
far=hi[2]+4*s-c[2]; near=hi[2]+0.3*s-c[2]
print(f'--target {c[0]},{c[1]},{c[2]} --eye {c[0]},{c[1]},{c[2]+far} --zoom {near/far} --fovy 30 --near {0.01*s} --far {8*s}')")
  echo "== fly-through ($FLY), 32 frames"
  "${MPI[@]}" $T render "$BFT" --size 1920x1080 --tiles 8x8 --frames 32 $FLY --decode-only "${CUT[@]}" --worker-cache-mb 2048 --out "$DIR/fly.png" --stats "$DIR/fly.jsonl" > /dev/null 2>&1
  report "$DIR/fly.jsonl"
fi
echo "(the model stays in $DIR; remove it when done)"
