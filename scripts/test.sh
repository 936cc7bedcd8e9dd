#!/usr/bin/env bash
# The test suite: every workspace crate's unit, integration and doc tests, in the
# optimised test profile (the round trips decode the 871k-triangle dragon).
# The tessera-bench crate's tests run too (its peers and the bandwidth experiment); its
# criterion benchmark does not: cargo bench -p tessera-bench
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh >/dev/null
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-/tmp/tessera-xdg}"
mkdir -p "$XDG_RUNTIME_DIR"
cargo test --workspace "$@"
