// The page tools/web/screenshot-tiles.mjs loads: a 3D Tiles tileset drawn by three.js and
// 3d-tiles-renderer from the camera in the address's query (eye — or several eyes separated by
// ';', one view after another —, target, up: world units, z up;
// fov: vertical degrees; width, height: pixels), as a white silhouette on black, or with
// look=own in the tiles' own materials (a baked scan's unlit vertex colors). Sets
// window.tilesReady once every tile the view needs is in and drawn; window.tilesError on errors.
import * as THREE from 'three';
import { TilesRenderer } from '3d-tiles-renderer';
import { GLTFExtensionsPlugin } from '3d-tiles-renderer/plugins';
import { MeshoptDecoder } from 'three/examples/jsm/libs/meshopt_decoder.module.js';

const query = new URLSearchParams(location.search);
const vector = (name) => new THREE.Vector3(...query.get(name).split(',').map(Number));
const width = Number(query.get('width'));
const height = Number(query.get('height'));

const renderer = new THREE.WebGLRenderer({ antialias: false, preserveDrawingBuffer: true });
renderer.setPixelRatio(1);
renderer.setSize(width, height);
renderer.setClearColor(0x000000, 1);
renderer.outputColorSpace = THREE.SRGBColorSpace;  // linear colors out as sRGB, as iso view writes
document.body.appendChild(renderer.domElement);

// One eye, or several separated by ';' (a fly-through: window.view(i) moves to the i-th).
const eyes = query.get('eye').split(';').map((e) => new THREE.Vector3(...e.split(',').map(Number)));
const target = vector('target');
const camera = new THREE.PerspectiveCamera(Number(query.get('fov')), width / height, 1, 2);
camera.up.copy(vector('up'));
function place(eye) {
  const distance = eye.distanceTo(target);
  camera.near = distance / 1000;
  camera.far = distance * 1000;
  camera.updateProjectionMatrix();
  camera.position.copy(eye);
  camera.lookAt(target);
  camera.updateMatrixWorld();
}
place(eyes[0]);

const scene = new THREE.Scene();
const white = new THREE.MeshBasicMaterial({ color: 0xffffff, side: THREE.DoubleSide });
const tiles = new TilesRenderer(query.get('tileset'));
tiles.registerPlugin(new GLTFExtensionsPlugin({ meshoptDecoder: MeshoptDecoder }));
tiles.errorTarget = Number(query.get('errorTarget') ?? 1);
tiles.setCamera(camera);
tiles.setResolutionFromRenderer(camera, renderer);
let models = 0;
tiles.addEventListener('load-model', ({ scene: model }) => {
  models++;
  if (query.get('look') !== 'own')
    model.traverse((object) => { if (object.isMesh) object.material = white; });
});
tiles.addEventListener('load-error', ({ error, url }) => {
  window.tilesError = `${url}: ${error}`;
});
scene.add(tiles.group);

// Frames until every tile the view needs is in and drawn (ten frames without a change); then
// window.tilesReady says what was loaded so far and what this view draws.
let settled = 0;
function frame() {
  tiles.update();
  renderer.render(scene, camera);
  settled = models > 0 && tiles.loadProgress === 1 ? settled + 1 : 0;
  if (settled >= 10) {
    window.tilesReady = { models, tiles: tiles.visibleTiles.size,
      triangles: renderer.info.render.triangles };
    return;
  }
  requestAnimationFrame(frame);
}
window.view = (i) => {
  window.tilesReady = null;
  settled = 0;
  place(eyes[i]);
  requestAnimationFrame(frame);
};
requestAnimationFrame(frame);
