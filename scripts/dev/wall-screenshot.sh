#!/usr/bin/env bash
# The README's picture of a live wall: a two-display wall (two 640x480 displays side by side,
# 40 pixels of bezel between them) shown by `render --present` under `mpirun -np 4` (rank 0,
# a worker and two display ranks, each opening its display's window where the wall file
# places it) on an Xvfb of its own; the camera turned with a drag in the first display's
# window, then the X screen read back with xwd, cropped, the screen around the windows grey.
#   scripts/dev/wall-screenshot.sh [MODEL] [OUT.png]   (default: the dragon, docs/live-wall.png)
set -euo pipefail
cd "$(dirname "$0")/../.."
model="${1:-../shared/meshes/stanford/dragon_vrip.ply.gz}"
out="${2:-docs/live-wall.png}"
bin=target/release/tessera
[ -x "$bin" ] || cargo build --release -q -p tessera
tmp=$(mktemp -d)
display=":$((300 + $$ % 300))"
Xvfb "$display" -screen 0 1400x600x24 -nolisten tcp >/dev/null 2>&1 &
xvfb=$!
trap 'kill $xvfb 2>/dev/null; rm -rf "$tmp"' EXIT
sleep 1
cat > "$tmp/wall.toml" <<'WALL'
[window]
x = 20
y = 20
[[display]]
name = "left"
x = 0
y = 0
width = 640
height = 480
bezel = [0, 0, 20, 0]
[[display]]
name = "right"
x = 680
y = 0
width = 640
height = 480
bezel = [20, 0, 0, 0]
WALL
export DISPLAY="$display" XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-/tmp/tessera-xdg}"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
mkdir -p "$XDG_RUNTIME_DIR"
mpirun --oversubscribe --bind-to none -np 4 -x DISPLAY "$bin" render "$model" --wall "$tmp/wall.toml" \
  --display-ranks 2 --present --tiles 4x2 --view three-quarter --control 127.0.0.1:0 2> "$tmp/log" &
run=$!
for _ in $(seq 600); do grep -q "control port on" "$tmp/log" && break; sleep 0.1; done
addr=$(sed -n 's/^tessera: control port on //p' "$tmp/log")
python3 scripts/tessera_control.py "$addr" status >/dev/null
left=$(xdotool search --sync --name "display left$" | head -1)
xdotool mousemove --window "$left" 300 240 mousedown 1 mousemove --window "$left" 340 250 mouseup 1
sleep 3
python3 scripts/tessera_control.py "$addr" status >/dev/null
sleep 2
xwd -root -silent | python3 scripts/dev/xwd-png.py "$out" 0 0 1360 520 20,20,640,480 700,20,640,480
python3 scripts/tessera_control.py "$addr" quit >/dev/null
wait $run
echo "wrote $out"
