// Shows a GLB exported by Radiosity Baker (?glb=URL, default cornell_box.glb; ?size=N pixels,
// square) through the file's
// own camera, lit only by its MOZ_lightmap (no lamps, no environment, no tone mapping), so what
// the page shows is albedo × baked lighting + emission, as the bake means it. ?strip=1 ignores
// MOZ_lightmap (a control: the lightmap must be what lights the scene). The title becomes
// "ready" once the first frame with the GLB is drawn, "error: …" on failure.
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { MozLightmapPlugin } from './moz_lightmap.js';

const query = new URLSearchParams(location.search);
const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(1);
const size = Number(query.get('size')) || Math.min(innerWidth, innerHeight);
renderer.setSize(size, size);  // square: the camera's aspect (the test crops the screenshot to it)
renderer.toneMapping = THREE.NoToneMapping;
renderer.outputColorSpace = THREE.SRGBColorSpace;
renderer.setClearColor(0x000000);
document.body.appendChild(renderer.domElement);

const loader = new GLTFLoader();
if (!query.get('strip')) loader.register((parser) => new MozLightmapPlugin(parser));
loader.load(query.get('glb') || 'cornell_box.glb', (gltf) => {
  const camera = gltf.cameras[0] || new THREE.PerspectiveCamera(40, 1, 0.1, 100);
  camera.aspect = 1;
  camera.updateProjectionMatrix();
  renderer.render(gltf.scene, camera);
  document.title = 'ready';
}, undefined, (error) => { document.title = `error: ${error}`; });
