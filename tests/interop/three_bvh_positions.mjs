// Reads BVH files with three.js's BVHLoader and plays them with an
// AnimationMixer, writing every bone's world position in every frame.
//
//   node three_bvh_positions.mjs MANIFEST.json
//
// MANIFEST.json: [{"bvh": "in.bvh", "out": "positions.csv", "frames": N}, ...]
// Each CSV has the lines of `gmr positions` (frame,joint,x,y,z, frames from 0),
// except that the joint column is "#k": the k-th node of the file's hierarchy
// in file order (three.js names every End Site "ENDSITE"; the test maps k to
// gmr's name for that node).
import { readFileSync, writeFileSync } from 'node:fs';
import { AnimationMixer, LoopOnce, Vector3 } from 'three';
import { BVHLoader } from 'three/addons/loaders/BVHLoader.js';

function positions(bvhPath, outPath, frames) {
  const text = readFileSync(bvhPath, 'utf8');
  const errors = [];
  const error = console.error;
  console.error = (...args) => errors.push(args.join(' '));  // BVHLoader reports problems this way and goes on
  let result;
  try {
    result = new BVHLoader().parse(text);
  } finally {
    console.error = error;
  }
  if (errors.length) throw new Error(errors.join('; '));
  const { skeleton, clip } = result;
  const bones = skeleton.bones;  // file order, End Sites included
  const root = bones[0];
  const mixer = new AnimationMixer(root);
  const action = mixer.clipAction(clip);
  action.setLoop(LoopOnce);  // the last frame must not wrap to the first
  action.clampWhenFinished = true;
  action.play();
  const lines = ['frame,joint,x,y,z'];
  const p = new Vector3();
  for (let f = 0; f < frames; f++) {
    // Keys sit at f * frameTime exactly as the loader computed them.
    mixer.setTime(clip.tracks.length ? clip.tracks[0].times[f] : 0);
    root.updateMatrixWorld(true);
    for (let k = 0; k < bones.length; k++) {
      bones[k].getWorldPosition(p);
      lines.push(`${f},#${k},${p.x},${p.y},${p.z}`);
    }
  }
  writeFileSync(outPath, lines.join('\n') + '\n');
}

const manifest = JSON.parse(readFileSync(process.argv[2], 'utf8'));
let failed = 0;
for (const item of manifest) {
  try {
    positions(item.bvh, item.out, item.frames);
    console.log(`three-bvh: ${item.bvh}: ${item.frames} frames`);
  } catch (e) {
    failed++;
    console.log(`three-bvh: ${item.bvh}: FAILED: ${e.message}`);
  }
}
process.exit(failed ? 1 : 0);
