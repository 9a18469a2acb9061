// Loads meshdeco .glb exports with three.js's GLTFLoader (Node, no browser) and prints, per file,
// one JSON line: the meshes' morph-target counts, the rest mesh's bounding box in the scene (world
// transforms applied) and its tallest axis, the animation clips and their key counts.
// Usage: THREE_DIR=<dir>/node_modules/three node three_bbox.mjs A.glb [B.glb ...]
import { readFileSync } from 'node:fs';
import { pathToFileURL } from 'node:url';
import path from 'node:path';

const threeDir = process.env.THREE_DIR;
if (!threeDir) throw new Error('set THREE_DIR to the three package directory');
const THREE = await import(pathToFileURL(path.join(threeDir, 'build/three.module.js')).href);
const { GLTFLoader } = await import(pathToFileURL(path.join(threeDir, 'examples/jsm/loaders/GLTFLoader.js')).href);

for (const file of process.argv.slice(2)) {
  const buf = readFileSync(file);
  const ab = buf.buffer.slice(buf.byteOffset, buf.byteOffset + buf.byteLength);
  const gltf = await new Promise((resolve, reject) => new GLTFLoader().parse(ab, '', resolve, reject));
  gltf.scene.updateMatrixWorld(true);
  const meshes = [];
  gltf.scene.traverse((o) => { if (o.isMesh) meshes.push(o); });
  const box = new THREE.Box3().setFromObject(gltf.scene);
  const size = box.getSize(new THREE.Vector3());
  const ext = [size.x, size.y, size.z];
  const tallest = 'XYZ'[ext.indexOf(Math.max(...ext))];
  console.log(JSON.stringify({
    file,
    meshes: meshes.length,
    morph_targets: meshes.map((m) => (m.geometry.morphAttributes.position || []).length),
    morph_normals: meshes.map((m) => (m.geometry.morphAttributes.normal || []).length),
    metalness: meshes.map((m) => m.material.metalness),
    double_sided: meshes.map((m) => m.material.side === THREE.DoubleSide),
    size: ext,
    tallest,
    clips: gltf.animations.map((a) => ({ name: a.name, keys: a.tracks[0] ? a.tracks[0].times.length : 0 })),
  }));
}
