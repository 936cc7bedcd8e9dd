#!/usr/bin/env bash
# Writes what users see from a `tessera` binary on the shared meshes into OUT, one file per
# output: `.bft` and `.dpm` files, `sort --dump` tiles, single-process and `mpirun -np 3`
# PNGs (sorted and progressive models, a tile wall) and `pm adapt` PLYs (CPU and GPU).
# scripts/dev/same-output.sh runs it for two builds and compares the folders byte for byte.
#   usage: scripts/dev/outputs.sh path/to/tessera OUT
set -euo pipefail
bin="$(realpath "$1")"
out="$2"
cd "$(dirname "$0")/../.."
meshes=../shared/meshes
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-/tmp/tessera-xdg}"
mkdir -p "$XDG_RUNTIME_DIR" "$out"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
mpi=(mpirun --oversubscribe --bind-to none -np 3)

# name=path: a scan, a large scan, a scan with holes, non-manifold and degenerate input.
models=(
  bunny=$meshes/stanford/bunny_zipper_c3d.obj.gz
  dragon=$meshes/stanford/dragon_vrip.ply.gz
  falcon=$meshes/odedstein/falconstatue_boundary.obj.gz
  nonmanifold=$meshes/degenerate/non_manifold_face_graph.obj
  fused=$meshes/degenerate/fused_vertices.obj
  spot=assets/spot.obj.gz
)
q() { "$@" >/dev/null 2>&1 || { echo "outputs.sh: failed: $*" >&2; exit 1; }; }

for m in "${models[@]}"; do
  name=${m%%=*} path=${m#*=}
  q "$bin" encode "$path" -o "$out/$name.bft"
  q "$bin" encode "$path" -o "$out/$name.q12.bft" --quant-bits 12
  q "$bin" pm build "$path" -o "$out/$name.dpm"
  rm -rf "$out/$name-tiles"
  q "$bin" sort "$out/$name.bft" --size 640x480 --tiles 4x4 --dump "$out/$name-tiles"
  q "$bin" pm adapt "$out/$name.dpm" --size 640x480 --error-px 0.5 -o "$out/$name-adapt.ply"
done

for name in bunny spot; do
  q "$bin" pm adapt "$out/$name.dpm" --size 640x480 --error-px 1 --gpu -o "$out/$name-adapt-gpu.ply"
  q "$bin" decode "$out/$name.bft" -o "$out/$name-decoded.obj"
done
q "$bin" render "$out/dragon.bft" --size 960x540 --tiles 1x1 --out "$out/dragon-1x1.png"
q "$bin" render "$out/bunny.bft" --size 640x480 --tiles 3x2 --frames 2 --orbit --out "$out/bunny-orbit.png"
q "$bin" render "$out/bunny.bft" --size 640x480 --tiles 2x2 --wall assets/wall.toml --out "$out/bunny-wall.png"
q "$bin" render "$out/bunny.dpm" --size 480x360 --tiles 2x2 --out "$out/bunny-pm.png"
q "${mpi[@]}" "$bin" render "$out/dragon.bft" --size 960x540 --tiles 4x4 --out "$out/dragon-np3.png"
q "${mpi[@]}" "$bin" render "$out/falcon.bft" --size 640x480 --tiles 3x3 --tile-coding range --out "$out/falcon-np3.png"
q "${mpi[@]}" "$bin" render "$out/bunny.dpm" --size 480x360 --tiles 2x2 --out "$out/bunny-pm-np3.png"
echo "outputs.sh: $(find "$out" -type f | wc -l) files in $out"
