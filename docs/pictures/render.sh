#!/usr/bin/env bash
# docs/pictures/render.sh [ISO_BINARY] — renders the README's picture strip from the bundled
# kitten scan (tests/data/kitten_normals.xyz), all three from one camera on a black sky:
#   scan.png     the raw points, drawn as image-space points (iso view SCAN --cpu)
#   surface.png  the converted surface, its light baked (iso convert, iso bake, iso view --cpu)
#   tiles.png    its 3D Tiles export drawn by three.js in headless Chromium
#                (iso export --tiles, tools/web/screenshot-tiles.mjs; needs `tools/run setup`)
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
iso=${1:-$root/build/bin/iso}
out=$root/docs/pictures
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

cat >"$tmp/scene.json" <<'SCENE'
{"sky_top": [0, 0, 0], "sky_bottom": [0, 0, 0], "ambient": [0.05, 0.05, 0.05],
 "lights": [{"type": "point", "position": [-1.8, 2.2, 1.4]}],
 "material": {"color": [0.9, 0.72, 0.5], "specular": 0}}
SCENE
eye=-0.9,0.55,1.6 target=0,-0.02,0 up=0,1,0
view=(--cpu --width 320 --height 240 --fov 40 --camera="$eye,$target,$up" --scene "$tmp/scene.json")

scan=$root/tests/data/kitten_normals.xyz
"$iso" view "$scan" "${view[@]}" --no-smooth --antialias off --out "$out/scan.png"
"$iso" convert -q "$scan" -o "$tmp/kitten.iso" >/dev/null
"$iso" bake "$tmp/kitten.iso" -o "$tmp/lit.iso" --scene "$tmp/scene.json" >/dev/null
"$iso" view "$tmp/lit.iso" "${view[@]}" --out "$out/surface.png"
"$iso" export "$tmp/lit.iso" --tiles "$tmp/tiles" >/dev/null
node "$root/tools/web/screenshot-tiles.mjs" "$tmp/tiles" "$out/tiles.png" \
  "$eye" "$target" "$up" 40 320 240 own
