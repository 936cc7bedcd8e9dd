#!/usr/bin/env bash
# The demo: sets up the system packages if needed, builds in release mode, and renders the
# bundled model sort-first with `mpirun -np 2` (rank 0 sorts the compressed model into
# tiles, rank 1 decodes and renders them with wgpu) from a three-quarter view that fills the
# frame (the bundled cow faces -Z, hence the azimuth), then prints the PNG's path.
#   scripts/demo.sh [MODEL] [extra tessera render flags...]   (default: assets/spot_colored.ply.gz, Spot with vertex colours)
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh >/dev/null
model="${1:-assets/spot_colored.ply.gz}"
shift || true
out="${TESSERA_OUT:-out}"
mkdir -p "$out"
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-/tmp/tessera-xdg}"
mkdir -p "$XDG_RUNTIME_DIR"
# Open MPI refuses to run as root unless told it may.
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
cargo build --release -q -p tessera
mpirun --oversubscribe --bind-to none -np 2 "${CARGO_TARGET_DIR:-target}/release/tessera" render "$model" \
  --size 1280x720 --tiles 4x4 --view three-quarter --azimuth -135 \
  --out "$out/frame.png" --stats "$out/stats.jsonl" "$@" 2>&1 | grep -v '^$' || exit 1
echo "demo frame: $out/frame.png (stats: $out/stats.jsonl)"
