#!/usr/bin/env bash
# Regenerates the glTF test files in codec/tests/gltf/ with real peer tools from the npm
# registry (obj2gltf, glTF Transform's CLI), from the shared cow.obj, and the hand-made
# one with make_handmade.py. The files are committed; this script says how they were made.
#   bash scripts/dev/gltf-fixtures.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
out=codec/tests/gltf
src=../shared/meshes/classic/cow.obj
tools=$(mktemp -d)
trap 'rm -rf "$tools"' EXIT
(cd "$tools" && npm install --silent obj2gltf@3.2.0 @gltf-transform/cli@4.5.1 >/dev/null)
bin=$tools/node_modules/.bin
cp "$src" "$tools/cow.obj"
"$bin/obj2gltf" -i "$tools/cow.obj" -o "$out/cow_embedded.gltf"
"$bin/obj2gltf" -i "$tools/cow.obj" -o "$out/separate/cow_separate.gltf" --separate
"$bin/obj2gltf" -i "$tools/cow.obj" -o "$out/cow.glb" -b
"$bin/gltf-transform" draco "$out/cow.glb" "$out/cow_draco.glb"
"$bin/gltf-transform" meshopt "$out/cow.glb" "$out/cow_meshopt.glb"
(cd "$out" && python3 make_handmade.py)
ls -la "$out" "$out/separate"
