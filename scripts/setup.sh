#!/usr/bin/env bash
# Installs every system package Tessera needs, idempotently, on Debian (as root, or with sudo).
#   Open MPI (mpirun + headers) for the cluster path, libclang for the `mpi` crate's bindgen,
#   Mesa's Vulkan drivers (lavapipe) so wgpu runs headless without a GPU, and GNU time
#   (/usr/bin/time), with which a test and the scale scripts measure peak memory, and ffmpeg
#   (with ffprobe), to which `render --out movie.mp4` pipes its frames; the X libraries
#   `tessera view` loads at run time (it opens them itself, so none is needed to build), and
#   Xvfb with xdotool and xwd (x11-apps), with which its tests open, drive and read back a
#   window without a screen.
# Safe to run again: packages already present are skipped and nothing is reinstalled.
set -euo pipefail

PACKAGES=(
  build-essential pkg-config
  openmpi-bin libopenmpi-dev
  libclang-dev clang
  mesa-vulkan-drivers libvulkan1 vulkan-tools
  time
  ffmpeg
  libx11-6 libx11-xcb1 libxcb1 libxcursor1 libxrandr2 libxi6 libxkbcommon-x11-0
  xvfb xdotool x11-apps
)

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "setup: all system packages present"
else
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
  echo "setup: installing ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

if ! command -v cargo >/dev/null 2>&1; then
  echo "setup: cargo not found; install the Rust toolchain with rustup (https://rustup.rs)" >&2
  exit 1
fi

# CI checks formatting and lints: the toolchain's rustfmt and clippy components.
if command -v rustup >/dev/null 2>&1; then
  for c in rustfmt clippy; do
    if ! rustup component list --installed 2>/dev/null | grep -q "^$c"; then
      echo "setup: adding the $c component"
      rustup component add "$c"
    fi
  done
fi
