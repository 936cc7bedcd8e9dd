#!/usr/bin/env bash
# Shows that a change leaves what users see byte-identical: builds `tessera` at REV (default
# origin/main, else main) and at the working tree, writes scripts/dev/outputs.sh's files with both,
# and compares every file. In `.bft` and `.dpm` files the version field and the header CRC
# (which covers no version, but moves with it in the comparison) are masked, so a version bump
# alone compares equal. JSON summaries are compared without their timings (keys ending in
# `_ms`) and with the output folder's name taken out; everything else must match byte for
# byte.
#   usage: scripts/dev/same-output.sh [REV]        (BASE_BIN=path skips building REV)
set -euo pipefail
cd "$(dirname "$0")/../.."
rev="${1:-main}"
work="$(mktemp -d /tmp/tessera-same.XXXXXX)"
trap 'git worktree remove --force "$work/src" >/dev/null 2>&1 || true; rm -rf "$work"' EXIT

if [ -z "${BASE_BIN:-}" ]; then
  git worktree add -q --detach "$work/src" "$rev"
  ln -s "$(realpath ../shared)" "$work/shared"
  echo "same-output: building $rev"
  CARGO_TARGET_DIR="${BASE_TARGET:-target/same-output-base}" cargo build -q --release -p tessera \
    --manifest-path "$work/src/Cargo.toml"
  BASE_BIN="${BASE_TARGET:-target/same-output-base}/release/tessera"
fi
echo "same-output: building the working tree"
cargo build -q --release -p tessera
scripts/dev/outputs.sh "$BASE_BIN" "$work/before"
scripts/dev/outputs.sh "${CARGO_TARGET_DIR:-target}/release/tessera" "$work/after"

python3 - "$work/before" "$work/after" <<'EOF'
import json, os, sys
before, after = sys.argv[1], sys.argv[2]
def files(root):
    return sorted(os.path.relpath(os.path.join(d, f), root) for d, _, fs in os.walk(root) for f in fs)
def untimed(v, root):
    if isinstance(v, dict):
        return {k: untimed(x, root) for k, x in v.items() if not k.endswith("_ms")}
    if isinstance(v, list):
        return [untimed(x, root) for x in v]
    return v.replace(root, "OUT") if isinstance(v, str) else v
def masked(path, root):
    if path.endswith(".json"):
        return json.dumps(untimed(json.load(open(path)), root), sort_keys=True).encode()
    b = bytearray(open(path, "rb").read())
    if b[:7] in (b"TESSBFT", b"TESSDPM") and len(b) >= 12:
        h = int.from_bytes(b[10:12], "little")
        b[8:10] = b"\0\0"
        b[12 + h:16 + h] = b"\0\0\0\0"
    return bytes(b)
a, b = files(before), files(after)
bad = sorted(set(a) ^ set(b))
for f in bad:
    print(f"only {'before' if f in a else 'after'}: {f}")
same = 0
for f in sorted(set(a) & set(b)):
    if masked(os.path.join(before, f), before) == masked(os.path.join(after, f), after):
        same += 1
    else:
        print(f"differs: {f}")
        bad.append(f)
print(f"same-output: {same} of {len(set(a) | set(b))} files identical")
sys.exit(1 if bad else 0)
EOF
