#!/usr/bin/env bash
# tests/readme_first_screen.sh ISO_BINARY [README] — runs the commands of README.md's first screen
# ("Your own scan": the code block between <!-- first-screen --> and <!-- /first-screen -->) on
# the bundled kitten scan, in a temporary directory, and checks that each wrote what it says.
#
# How it adapts each line:
#  - the README's input file name, my-scan.las, becomes tests/data/kitten_normals.xyz (every other
#    name, such as my-scan.iso, stays: it is made by the lines above it);
#  - a leading build/bin/iso becomes ISO_BINARY; a trailing # comment is dropped;
#  - `iso view FILE` without --out, --headless, --cpu or --bench (a window) runs as
#    `iso view FILE --cpu --out view-N.png --width 256 --height 192`: the CPU reference tracer draws
#    the same picture without a display or a GPU.
# What it checks, by command: convert and bake: the -o file exists and `iso verify` accepts it;
# view: the picture is a PNG; export: --tiles DIR holds tileset.json and a .glb, a --mesh .glb
# starts with glTF's magic, other outputs exist and are not empty; gen: the -o file is not empty;
# info: it prints the file's format; eval: it prints a JSON object; anything else: exit status 0.
# Fails if the block is missing, holds no convert line, or names no my-scan.las.
set -euo pipefail

[ $# -ge 1 ] || { echo "usage: $0 ISO_BINARY [README]" >&2; exit 2; }
iso=$(realpath "$1")
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
readme=$(realpath "${2:-$root/README.md}")
sample=$root/tests/data/kitten_normals.xyz
placeholder=my-scan.las

fail() { echo "readme_first_screen: $*" >&2; exit 1; }
[ -x "$iso" ] || fail "$iso is not a program"
[ -f "$sample" ] || fail "$sample is missing"

# The lines of the first code block between the markers, without blank lines and comments.
mapfile -t lines < <(awk '
  /<!-- first-screen -->/ { inside = 1; next }
  /<!-- \/first-screen -->/ { inside = 0 }
  inside && /^```/ { fence = !fence; if (!fence) exit; next }
  inside && fence { sub(/[ \t]+#.*$/, ""); sub(/^[ \t]*#.*$/, ""); if ($0 ~ /[^ \t]/) print }
' "$readme")
[ ${#lines[@]} -gt 0 ] || fail "$readme: no code block between <!-- first-screen --> and <!-- /first-screen -->"
printf '%s\n' "${lines[@]}" | grep -q "^build/bin/iso convert " ||
  fail "$readme: the first screen has no 'build/bin/iso convert' line"
printf '%s\n' "${lines[@]}" | grep -qF "$placeholder" ||
  fail "$readme: the first screen names no $placeholder (the input this script replaces)"

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cd "$work"

# The value after any of the options given, in the words of a command.
value_of() {
  local -n words_=$1
  shift
  local i option
  for ((i = 0; i + 1 < ${#words_[@]}; i++)); do
    for option in "$@"; do
      [ "${words_[i]}" = "$option" ] && { echo "${words_[i + 1]}"; return 0; }
    done
  done
  return 1
}
nonempty() { [ -s "$1" ] || fail "line $n: $2 did not write $1"; }

n=0
for line in "${lines[@]}"; do
  n=$((n + 1))
  case $line in
    *[\"\'\$\`\;\&\|\<\>\(\)]*) fail "line $n: '$line' has shell syntax this script does not run" ;;
    build/bin/iso\ *) ;;
    *) fail "line $n: '$line' does not start with build/bin/iso" ;;
  esac
  read -ra words <<<"${line#build/bin/iso }"
  for i in "${!words[@]}"; do
    [ "${words[i]}" = "$placeholder" ] && words[i]=$sample
  done
  command=${words[0]}
  if [ "$command" = view ] && ! printf '%s\n' "${words[@]}" | grep -qxE -- '-o|--out|--headless|--cpu|--bench'; then
    words+=(--cpu --out "view-$n.png" --width 256 --height 192)
  fi
  echo "readme_first_screen: line $n: iso ${words[*]}"
  output=$("$iso" "${words[@]}") || fail "line $n: iso ${words[*]} failed"
  case $command in
    convert | bake)
      file=$(value_of words -o --output) || fail "line $n: no -o"
      nonempty "$file" "$command"
      "$iso" verify "$file" >/dev/null || fail "line $n: iso verify rejects $file" ;;
    view)
      file=$(value_of words -o --out) || fail "line $n: no picture"
      nonempty "$file" view
      [ "$(head -c 4 "$file" | tail -c 3)" = PNG ] || fail "line $n: $file is not a PNG" ;;
    export)
      ok=0
      if dir=$(value_of words --tiles); then
        nonempty "$dir/tileset.json" export
        compgen -G "$dir/*.glb" >/dev/null || fail "line $n: $dir holds no .glb tile"
        ok=1
      fi
      if file=$(value_of words --mesh); then
        nonempty "$file" export
        case $file in *.glb) [ "$(head -c 4 "$file")" = glTF ] || fail "line $n: $file is not glTF binary" ;; esac
        ok=1
      fi
      for option in --vdb --points --volume-points; do
        if file=$(value_of words "$option"); then nonempty "$file" export; ok=1; fi
      done
      [ $ok -eq 1 ] || fail "line $n: export writes nothing this script knows" ;;
    gen)
      file=$(value_of words -o --output) || fail "line $n: no -o"
      nonempty "$file" gen ;;
    info)
      grep -q '^format ' <<<"$output" || fail "line $n: iso info printed no format line" ;;
    eval)
      [ "${output:0:1}" = "{" ] || fail "line $n: iso eval printed no JSON object" ;;
  esac
done
echo "readme_first_screen: the README's ${#lines[@]} first-screen commands ran on $(basename "$sample")"
