#!/usr/bin/env bash
# The demo: sets up the system packages if needed, builds in release mode, encodes the
# bundled model into a .bft, prints its stats, and decodes it back to a PLY.
#   scripts/demo.sh [MODEL]      (default: assets/spot.obj.gz)
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh >/dev/null
model="${1:-assets/spot.obj.gz}"
out="${TESSERA_OUT:-out}"
mkdir -p "$out"
cargo build --release -q -p tessera
bin=target/release/tessera
name=$(basename "$model"); name="${name%%.*}"
"$bin" encode "$model" -o "$out/$name.bft"
"$bin" stats "$out/$name.bft"
"$bin" decode "$out/$name.bft" -o "$out/$name.ply"
echo "demo output: $out/$name.bft, $out/$name.ply"
