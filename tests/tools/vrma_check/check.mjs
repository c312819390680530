// Reads a VRM Animation (.vrma) written by kinemo the way VRM apps on the web
// do (three.js's GLTFLoader with @pixiv/three-vrm-animation's
// VRMAnimationLoaderPlugin), poses the humanoid from what the plugin read,
// and compares it with kinemo's BVH of the same retarget (the motion on the
// VRM's own skeleton, written by another code path):
//
//   node check.mjs --vrma OUT.vrma --bvh OUT.bvh --vrm RIG.vrm [--every N]
//
// The humanoid is posed by forward kinematics over the file's bone nodes:
// each bone's rest offset (the node's translation; VRMC_vrm_animation rests
// in the T-pose) turned by its parent's world rotation, each world rotation
// the parent's times the plugin's track value; the hips at the plugin's hips
// track. The BVH is posed by its own channels (Euler angles in channel order,
// position channels replacing the OFFSET). A VRM 0.x character faces -Z and
// VRM Animations face +Z, so for one the BVH's x and z are negated.
// Prints one JSON line; exits 1 when a hand or foot differs by more than
// 2 mm at a compared frame or the file lacks what a VRM app needs.
import fs from 'fs';
import * as THREE from 'three';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';
import { VRMAnimationLoaderPlugin } from '@pixiv/three-vrm-animation';

function args() {
  const out = { every: 50 };
  const a = process.argv.slice(2);
  for (let i = 0; i < a.length; i += 2) out[a[i].replace(/^--/, '')] = a[i + 1];
  for (const k of ['vrma', 'bvh', 'vrm']) if (!out[k]) throw new Error(`--${k} is required`);
  out.every = Number(out.every);
  return out;
}

function glbJson(path) {
  const b = fs.readFileSync(path);
  if (b.toString('latin1', 0, 4) !== 'glTF') throw new Error(`${path}: not a GLB`);
  const len = b.readUInt32LE(12);
  return JSON.parse(b.toString('utf8', 20, 20 + len));
}

// The VRM's humanoid: bone name -> node name, and whether it is VRM 0.x.
function vrmBones(path) {
  const j = glbJson(path);
  const out = {};
  if (j.extensions && j.extensions.VRMC_vrm) {
    for (const [bone, v] of Object.entries(j.extensions.VRMC_vrm.humanoid.humanBones)) out[bone] = j.nodes[v.node].name;
    return { bones: out, vrm0: false };
  }
  for (const b of j.extensions.VRM.humanoid.humanBones) out[b.bone] = j.nodes[b.node].name;
  return { bones: out, vrm0: true };
}

function parseBvh(text) {
  const tok = text.split(/\s+/).filter((s) => s.length);
  let i = 0;
  const joints = [];
  const stack = [];
  let channels = 0;
  while (i < tok.length && tok[i] !== 'MOTION') {
    const t = tok[i++];
    if (t === 'ROOT' || t === 'JOINT') {
      joints.push({ name: tok[i++], parent: stack.length ? stack[stack.length - 1] : -1, offset: null, channels: [] });
      stack.push(joints.length - 1);
    } else if (t === 'End') {
      i++;  // "Site"
      stack.push(-2);
    } else if (t === 'OFFSET') {
      const o = [Number(tok[i]), Number(tok[i + 1]), Number(tok[i + 2])];
      i += 3;
      const top = stack[stack.length - 1];
      if (top >= 0 && joints[top].offset === null) joints[top].offset = o;
    } else if (t === 'CHANNELS') {
      const n = Number(tok[i++]);
      const top = stack[stack.length - 1];
      joints[top].first = channels;
      for (let k = 0; k < n; k++) joints[top].channels.push(tok[i++]);
      channels += n;
    } else if (t === '}') {
      stack.pop();
    }
  }
  i++;  // MOTION
  i++;  // Frames:
  const frames = Number(tok[i++]);
  i += 2;  // Frame Time:
  const frameTime = Number(tok[i++]);
  const values = [];
  for (let f = 0; f < frames; f++) {
    values.push(tok.slice(i, i + channels).map(Number));
    i += channels;
  }
  return { joints, frames: values, frameTime };
}

const AXES = { X: new THREE.Vector3(1, 0, 0), Y: new THREE.Vector3(0, 1, 0), Z: new THREE.Vector3(0, 0, 1) };

// World positions of every BVH joint at frame f.
function bvhPose(bvh, f) {
  const row = bvh.frames[f];
  const pos = [];
  const rot = [];
  bvh.joints.forEach((j, k) => {
    const t = new THREE.Vector3(...j.offset);
    const q = new THREE.Quaternion();
    j.channels.forEach((c, n) => {
      const v = row[j.first + n];
      const axis = c[0].toUpperCase();
      if (c.endsWith('position')) t.setComponent('XYZ'.indexOf(axis), v);
      else q.multiply(new THREE.Quaternion().setFromAxisAngle(AXES[axis], THREE.MathUtils.degToRad(v)));
    });
    if (j.parent < 0) {
      pos[k] = t;
      rot[k] = q;
    } else {
      pos[k] = t.applyQuaternion(rot[j.parent]).add(pos[j.parent]);
      rot[k] = rot[j.parent].clone().multiply(q);
    }
  });
  return pos;
}

function loadVrma(path) {
  const buf = fs.readFileSync(path);
  const ab = buf.buffer.slice(buf.byteOffset, buf.byteOffset + buf.byteLength);
  const loader = new GLTFLoader();
  loader.register((parser) => new VRMAnimationLoaderPlugin(parser));
  return new Promise((resolve, reject) => loader.parse(ab, '', resolve, reject));
}

// The value of a keyframe track at key k (the file keys every frame).
function key(track, k, size) {
  return Array.from(track.values.slice(k * size, k * size + size));
}

async function main() {
  const a = args();
  const gltf = await loadVrma(a.vrma);
  const anims = gltf.userData.vrmAnimations || [];
  if (anims.length !== 1) throw new Error(`the plugin read ${anims.length} VRM animations`);
  const anim = anims[0];
  const json = gltf.parser.json;
  const ext = json.extensions.VRMC_vrm_animation;
  const boneNode = Object.fromEntries(Object.entries(ext.humanoid.humanBones).map(([b, v]) => [b, v.node]));
  const boneOfNode = Object.fromEntries(Object.entries(boneNode).map(([b, n]) => [n, b]));
  const parentNode = {};
  json.nodes.forEach((n, i) => (n.children || []).forEach((c) => (parentNode[c] = i)));
  const rot = anim.humanoidTracks.rotation;
  const hipsTrack = anim.humanoidTracks.translation.get('hips');
  if (!hipsTrack) throw new Error('no hips translation track');
  const frames = hipsTrack.times.length;
  // Bones in parent-first order.
  const order = Object.keys(boneNode).sort((x, y) => boneNode[x] - boneNode[y]);
  for (const b of order) {
    if (b !== 'hips' && boneOfNode[parentNode[boneNode[b]]] === undefined) throw new Error(`${b}: its parent is no bone`);
  }
  const pose = (k) => {
    const world = {};
    const wrot = {};
    for (const b of order) {
      const q = rot.has(b) ? new THREE.Quaternion(...key(rot.get(b), k, 4)) : new THREE.Quaternion();
      if (b === 'hips') {
        world[b] = new THREE.Vector3(...key(hipsTrack, k, 3));
        wrot[b] = q;
      } else {
        const p = boneOfNode[parentNode[boneNode[b]]];
        const t = new THREE.Vector3(...json.nodes[boneNode[b]].translation);
        world[b] = t.applyQuaternion(wrot[p]).add(world[p]);
        wrot[b] = wrot[p].clone().multiply(q);
      }
    }
    return world;
  };

  const { bones: vrmBone, vrm0 } = vrmBones(a.vrm);
  const bvh = parseBvh(fs.readFileSync(a.bvh, 'utf8'));
  if (bvh.frames.length !== frames) throw new Error(`the BVH has ${bvh.frames.length} frames, the VRMA ${frames}`);
  const jointIndex = Object.fromEntries(bvh.joints.map((j, k) => [j.name, k]));
  const ends = ['leftHand', 'rightHand', 'leftFoot', 'rightFoot', 'head'];
  let worst = 0;
  let compared = 0;
  for (let f = 0; f < frames; f += a.every) {
    const v = pose(f);
    const b = bvhPose(bvh, f);
    for (const e of ends) {
      const j = jointIndex[vrmBone[e]];
      if (j === undefined) throw new Error(`${e}: ${vrmBone[e]} is not a joint of the BVH`);
      const p = b[j].clone();
      if (vrm0) p.set(-p.x, p.y, -p.z);
      worst = Math.max(worst, p.distanceTo(v[e]));
    }
    compared++;
  }
  // The face: each preset expression track's range, and blinks (a blink
  // track's rises through 0.5).
  const presets = {};
  for (const [name, track] of anim.expressionTracks.preset) {
    const w = Array.from(track.values);
    let rises = 0;
    for (let k = 1; k < w.length; k++) rises += w[k - 1] < 0.5 && w[k] >= 0.5;
    presets[name] = { min: Math.min(...w), max: Math.max(...w), rises };
  }
  const out = {
    bones: order.length,
    rotation_tracks: rot.size,
    frames,
    duration_s: anim.duration,
    rest_hips_m: anim.restHipsPosition.toArray(),
    frames_compared: compared,
    max_end_error_m: worst,
    presets,
  };
  console.log(JSON.stringify(out));
  const problems = [];
  if (worst > 0.002) problems.push(`a hand, foot or the head differs from the BVH by ${worst} m`);
  if (rot.size < 15) problems.push(`only ${rot.size} bones have rotation tracks`);
  if (problems.length) {
    console.error(`FAIL: ${problems.join('; ')}`);
    process.exit(1);
  }
}

main().catch((e) => {
  console.error(`FAIL: ${e.stack || e}`);
  process.exit(1);
});
