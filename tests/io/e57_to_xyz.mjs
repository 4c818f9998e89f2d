// An independent E57 reader for the E57 reader's tests: npm web-e57 (the Rust e57 crate compiled to
// WebAssembly) converts each E57 file to its XYZ text, one point per line: x y z in world
// coordinates (pose applied, spherical coordinates converted, invalid points left out), then
// "r g b" (0-255) when the point has a color, or its intensity as a grey "i i i" when it has no
// color. The module is instantiated here rather than imported, so that no node flag is needed.
//
//   node tests/io/e57_to_xyz.mjs <folder holding node_modules/web-e57> <in.e57> <out.xyz> [...]
//
// Exits 1 with the reason on stderr when a file cannot be converted.
import { readFileSync, writeFileSync } from "node:fs";
import { join } from "node:path";
import { pathToFileURL } from "node:url";

const [webTools, ...files] = process.argv.slice(2);
if (!webTools || files.length === 0 || files.length % 2 !== 0) {
  console.error("usage: e57_to_xyz.mjs <web tools folder> <in.e57> <out.xyz> [<in> <out>]...");
  process.exit(2);
}
const folder = join(webTools, "node_modules", "web-e57");
const glue = await import(pathToFileURL(join(folder, "e57_bg.js")).href);
const { instance } = await WebAssembly.instantiate(readFileSync(join(folder, "e57_bg.wasm")), {
  "./e57_bg.js": glue,
});
glue.__wbg_set_wasm(instance.exports);

for (let i = 0; i < files.length; i += 2) {
  try {
    const xyz = glue.convertE57(new Uint8Array(readFileSync(files[i])), "XYZ");
    writeFileSync(files[i + 1], xyz);
  } catch (error) {
    console.error(`${files[i]}: ${error}`);
    process.exit(1);
  }
}
