// The page tools/web/screenshot-tiles.mjs loads: a 3D Tiles tileset drawn by three.js and
// 3d-tiles-renderer from the camera in the address's query (eye, target, up: world units, z up;
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

const eye = vector('eye');
const target = vector('target');
const distance = eye.distanceTo(target);
const camera = new THREE.PerspectiveCamera(Number(query.get('fov')), width / height,
  distance / 1000, distance * 1000);
camera.up.copy(vector('up'));
camera.position.copy(eye);
camera.lookAt(target);
camera.updateMatrixWorld();

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

let settled = 0;
function frame() {
  tiles.update();
  renderer.render(scene, camera);
  settled = models > 0 && tiles.loadProgress === 1 ? settled + 1 : 0;
  if (settled >= 10) {
    window.tilesReady = { models, triangles: renderer.info.render.triangles };
    return;
  }
  requestAnimationFrame(frame);
}
requestAnimationFrame(frame);
