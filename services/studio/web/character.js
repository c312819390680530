// kinemo studio: a skinned glTF character, drawn by the page's own code.
//
// The studio (services/studio/core/character.h) retargets the motion onto
// the character's rig and sends, per frame, each joint node's local rotation
// and the hips' translation (CharacterMotion). This module reads the GLB
// itself (JSON and BIN chunks, accessors, skins, nodes, materials).
// CharacterRig holds a pose and computes the node world matrices from it
// (the page's main thread poses one per view; world matrices only when
// asked for). CharacterModel draws a rig (render.js, in the renderer's
// worker): it skins on the GPU, a vertex shader doing linear-blend skinning
// (Σ wᵢ · jointWorldᵢ · inverseBindᵢ · v) with the joint matrices in a
// uniform array, and a fragment shader lighting the surface (hemisphere +
// one sun + a little specular). three.js (Debian's libjs-three) only holds
// the scene, camera and draw calls.
//
// The mouth: the bundled characters have no face morphs and no jaw bone, so
// the page draws one: a dark ellipse on the face, skinned to the head bone,
// whose opening and width follow the viseme weights (MOUTH_SHAPES).
import * as THREE from '/three/build/three.module.js';

const GLB_MAGIC = 0x46546c67;   // "glTF"
const CHUNK_JSON = 0x4e4f534a;
const CHUNK_BIN = 0x004e4942;
const COMPONENTS = { SCALAR: 1, VEC2: 2, VEC3: 3, VEC4: 4, MAT4: 16 };

// A GLB's JSON and binary chunk. Errors name the file.
export function parseGlb(buffer, name) {
  const fail = (why) => { throw new Error(`${name}: ${why}`); };
  if (buffer.byteLength < 20) fail('too short for a GLB');
  const dv = new DataView(buffer);
  if (dv.getUint32(0, true) !== GLB_MAGIC) fail('not a GLB (it does not start with "glTF")');
  if (dv.getUint32(4, true) !== 2) fail(`glTF version ${dv.getUint32(4, true)}, not 2`);
  let json = null, bin = null;
  for (let offset = 12; offset + 8 <= buffer.byteLength;) {
    const length = dv.getUint32(offset, true), type = dv.getUint32(offset + 4, true);
    const start = offset + 8;
    if (start + length > buffer.byteLength) fail('a chunk runs past the end of the file');
    if (type === CHUNK_JSON) json = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, start, length)));
    else if (type === CHUNK_BIN && !bin) bin = new DataView(buffer, start, length);
    offset = start + length + ((4 - (length % 4)) % 4);
  }
  if (!json) fail('no JSON chunk');
  return { json, bin, name };
}

// Accessor `index` as a Float32Array (or Uint32Array for integer data when
// `integers`), `count` × components values; normalized integers scaled to [0, 1].
function readAccessor(glb, index, integers = false) {
  const { json, bin, name } = glb;
  const a = json.accessors && json.accessors[index];
  if (!a) throw new Error(`${name}: accessors[${index}] missing`);
  if (a.sparse) throw new Error(`${name}: accessors[${index}] is sparse (not supported)`);
  const n = COMPONENTS[a.type];
  const out = integers ? new Uint32Array(a.count * n) : new Float32Array(a.count * n);
  if (a.bufferView === undefined) return out;  // all zeros by the specification
  const view = json.bufferViews[a.bufferView];
  if (!view || (view.buffer || 0) !== 0 || !bin) throw new Error(`${name}: accessors[${index}] is not in the GLB's binary chunk`);
  const size = { 5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4 }[a.componentType];
  if (!size) throw new Error(`${name}: accessors[${index}].componentType ${a.componentType} unknown`);
  const stride = view.byteStride || size * n;
  const base = (view.byteOffset || 0) + (a.byteOffset || 0);
  if (a.count > 0 && base + stride * (a.count - 1) + size * n > bin.byteLength) {
    throw new Error(`${name}: accessors[${index}] runs past the binary chunk`);
  }
  const get = {
    5120: (o) => bin.getInt8(o), 5121: (o) => bin.getUint8(o), 5122: (o) => bin.getInt16(o, true),
    5123: (o) => bin.getUint16(o, true), 5125: (o) => bin.getUint32(o, true), 5126: (o) => bin.getFloat32(o, true),
  }[a.componentType];
  const scale = a.normalized ? { 5120: 1 / 127, 5121: 1 / 255, 5122: 1 / 32767, 5123: 1 / 65535 }[a.componentType] || 1 : 1;
  for (let i = 0, k = 0; i < a.count; ++i) {
    const o = base + i * stride;
    for (let c = 0; c < n; ++c) out[k++] = get(o + c * size) * scale;
  }
  return out;
}

// ---------------------------------------------------------------- shaders

const VERTEX = `
  #define MAX_JOINTS %JOINTS%
  uniform mat4 jointMatrices[MAX_JOINTS];
  attribute vec4 skinJoint;
  attribute vec4 skinWeight;
  varying vec3 vNormal;
  varying vec3 vWorld;
  varying vec2 vUv;
  void main() {
    mat4 skin = skinWeight.x * jointMatrices[int(skinJoint.x)] + skinWeight.y * jointMatrices[int(skinJoint.y)] +
                skinWeight.z * jointMatrices[int(skinJoint.z)] + skinWeight.w * jointMatrices[int(skinJoint.w)];
    vec4 world = modelMatrix * skin * vec4(position, 1.0);
    vNormal = normalize(mat3(modelMatrix) * mat3(skin) * normal);
    vWorld = world.xyz;
    vUv = uv;
    gl_Position = projectionMatrix * viewMatrix * world;
  }`;

const FRAGMENT = `
  uniform vec4 baseColor;
  uniform sampler2D map;
  uniform vec3 sunDirection;
  varying vec3 vNormal;
  varying vec3 vWorld;
  varying vec2 vUv;
  void main() {
  #ifdef BASE_COLOR_MAP
    vec3 albedo = baseColor.rgb * pow(texture2D(map, vUv).rgb, vec3(2.2));
  #else
    vec3 albedo = baseColor.rgb;  // no texture to sample
  #endif
    vec3 n = normalize(vNormal);
    if (!gl_FrontFacing) n = -n;
    vec3 toEye = normalize(cameraPosition - vWorld);
    float hemi = 0.5 + 0.5 * n.y;
    float sun = max(dot(n, sunDirection), 0.0);
    float spec = pow(max(dot(n, normalize(sunDirection + toEye)), 0.0), 32.0) * 0.12;
    vec3 linear = albedo * (mix(vec3(0.20, 0.21, 0.24), vec3(0.55, 0.56, 0.58), hemi) + 1.1 * sun) + spec;
    gl_FragColor = vec4(pow(linear, vec3(1.0 / 2.2)), 1.0);
  }`;

const WHITE = new THREE.DataTexture(new Uint8Array([255, 255, 255, 255]), 1, 1, THREE.RGBAFormat);
WHITE.needsUpdate = true;
const SUN = new THREE.Vector3(0.45, 0.8, 0.55).normalize();

function skinMaterial(joints, color, map) {
  return new THREE.ShaderMaterial({
    vertexShader: VERTEX.replace('%JOINTS%', String(Math.max(joints, 1))),
    fragmentShader: FRAGMENT,
    defines: map ? { BASE_COLOR_MAP: '' } : {},
    uniforms: {
      jointMatrices: { value: new Float32Array(Math.max(joints, 1) * 16) },
      baseColor: { value: new THREE.Vector4(...color) },
      map: { value: map || WHITE },
      sunDirection: { value: SUN },
    },
    side: THREE.DoubleSide,
  });
}

// ---------------------------------------------------------------- mouth

// Viseme category -> [opening 0..1, width factor]: open vowels open wide,
// rounded ones (OW, W_UW) narrow, bilabials (B_P_M) and silence close.
const MOUTH_SHAPES = {
  PAU: [0, 1], B_P_M: [0, 0.95], F_V: [0.15, 1], TH_DH: [0.3, 1], S_Z_ZH: [0.2, 1.05], N_D_T_L: [0.35, 1],
  R: [0.35, 0.85], K_G_NG: [0.45, 1], CH_SH_JH: [0.4, 0.8], HH: [0.55, 1], EY: [0.6, 1.1], AA: [1, 1],
  AO: [0.85, 0.85], OW: [0.7, 0.65], W_UW: [0.4, 0.55],
};
const MOUTH_SEGMENTS = 24;

// The mouth's openness and width from one viseme frame (weights by category name).
export function mouthShape(weights) {
  let open = 0, width = 0, total = 0;
  for (const [category, w] of Object.entries(weights)) {
    const shape = MOUTH_SHAPES[category];
    if (!shape || !(w > 0)) continue;
    open += w * shape[0];
    width += w * shape[1];
    total += w;
  }
  // Weights that sum past 1 (independent scores) are averaged.
  return { open: Math.min(open / Math.max(total, 1), 1), width: total > 0 ? width / total : 1 };
}

// ---------------------------------------------------------------- the character

const tmpQ = new THREE.Quaternion(), tmpT = new THREE.Vector3(), tmpS = new THREE.Vector3();
const tmpM = new THREE.Matrix4();

// A character's rig and pose, without drawing: the page's main thread
// poses it (hands for stats(), fit) and the renderer (render-worker.js)
// keeps its own copy to skin from. World matrices are computed when asked
// for (update() after setFrame), not per received frame.
export class CharacterRig {
  // `glb` from parseGlb, `info` the studio's CharacterInfo, `maxUniforms`
  // the WebGL context's MAX_VERTEX_UNIFORM_VECTORS.
  constructor(glb, info, maxUniforms) {
    this.glb = glb;
    this.info = info;
    this.name = info.name;
    const { json } = glb;
    const nodes = json.nodes || [];
    // Nodes, parents first.
    this.parent = new Int32Array(nodes.length).fill(-1);
    nodes.forEach((n, i) => (n.children || []).forEach((c) => { this.parent[c] = i; }));
    this.order = [];
    const visit = (i) => { this.order.push(i); (nodes[i].children || []).forEach(visit); };
    nodes.forEach((n, i) => { if (this.parent[i] < 0) visit(i); });
    this.defaults = nodes.map((n) => {
      if (n.matrix) return new THREE.Matrix4().fromArray(n.matrix);
      const m = new THREE.Matrix4();
      m.compose(new THREE.Vector3(...(n.translation || [0, 0, 0])), new THREE.Quaternion(...(n.rotation || [0, 0, 0, 1])),
                new THREE.Vector3(...(n.scale || [1, 1, 1])));
      return m;
    });
    this.scales = nodes.map((n) => new THREE.Vector3(...(n.scale || [1, 1, 1])));
    this.world = nodes.map(() => new THREE.Matrix4());
    // The rig's joints as the studio sends them.
    this.jointNodes = (info.joints || []).map((j) => j.node);
    this.jointOfNode = new Map(this.jointNodes.map((n, j) => [n, j]));
    this.bindTranslation = info.bindTranslations || [];
    this.translated = info.translatedJoints || [];
    this.translatedSlot = new Map(this.translated.map((j, t) => [j, t]));
    this.rotations = new Float32Array(this.jointNodes.length * 4);
    this.translations = new Float32Array(this.translated.length * 3);
    this.restPose();
    // Skins: joint nodes and inverse bind matrices.
    this.skins = (json.skins || []).map((s, i) => {
      const joints = s.joints || [];
      if (joints.length * 4 + 32 > maxUniforms) {
        throw new Error(`${glb.name}: skins[${i}] has ${joints.length} joints; this GPU skins at most ` +
                        `${Math.floor((maxUniforms - 32) / 4)}`);
      }
      const ibm = s.inverseBindMatrices !== undefined ? readAccessor(glb, s.inverseBindMatrices)
        : new Float32Array(joints.length * 16).map((_, k) => (k % 5 === 0 ? 1 : 0));
      return { joints, ibm };
    });
    this.hands = ['left_hand', 'right_hand'].map((role) => (info.joints || []).findIndex((j) => j.role === role))
      .filter((j) => j >= 0);
    this.update();
    this.fit();
  }

  // The rig at rest (no frame yet): identity rotations are not the rest of a
  // glTF rig; the node defaults are (with the bind translations).
  restPose() {
    const nodes = this.glb.json.nodes || [];
    this.jointNodes.forEach((node, j) => {
      const r = nodes[node].rotation || [0, 0, 0, 1];
      this.rotations.set(r, 4 * j);
    });
    this.translated.forEach((j, t) => {
      for (let c = 0; c < 3; ++c) this.translations[3 * t + c] = this.bindTranslation[3 * j + c] || 0;
    });
    this.stale = true;
  }

  // One frame of a CharacterMotion (already decoded into Float32Arrays);
  // `alpha` blends towards frame f + 1 (normalised lerp).
  setFrame(motion, f, alpha = 0) {
    const nj = this.jointNodes.length, nt = this.translated.length;
    const last = motion.frames - 1;
    const f0 = Math.min(Math.max(f, 0), last), f1 = Math.min(f0 + 1, last);
    const r0 = motion.rotations.subarray(f0 * nj * 4, (f0 + 1) * nj * 4);
    const r1 = motion.rotations.subarray(f1 * nj * 4, (f1 + 1) * nj * 4);
    for (let j = 0; j < nj; ++j) {
      const o = 4 * j;
      const sign = r0[o] * r1[o] + r0[o + 1] * r1[o + 1] + r0[o + 2] * r1[o + 2] + r0[o + 3] * r1[o + 3] < 0 ? -1 : 1;
      let len = 0;
      for (let c = 0; c < 4; ++c) {
        const v = r0[o + c] * (1 - alpha) + sign * r1[o + c] * alpha;
        this.rotations[o + c] = v;
        len += v * v;
      }
      len = Math.sqrt(len) || 1;
      for (let c = 0; c < 4; ++c) this.rotations[o + c] /= len;
    }
    for (let k = 0; k < nt * 3; ++k) {
      this.translations[k] = motion.translations[f0 * nt * 3 + k] * (1 - alpha) + motion.translations[f1 * nt * 3 + k] * alpha;
    }
    this.stale = true;
  }

  // A pose as setFrame leaves it (the renderer's copy gets the page's).
  setPose(rotations, translations) {
    this.rotations.set(rotations);
    this.translations.set(translations);
    this.stale = true;
  }

  // Node world matrices of the current pose (when it changed since).
  update() {
    if (!this.stale) return;
    this.stale = false;
    for (const n of this.order) {
      const j = this.jointOfNode.get(n);
      let local = this.defaults[n];
      if (j !== undefined) {
        const t = this.translatedSlot.get(j);
        if (t !== undefined) tmpT.fromArray(this.translations, 3 * t);
        else tmpT.set(this.bindTranslation[3 * j] || 0, this.bindTranslation[3 * j + 1] || 0, this.bindTranslation[3 * j + 2] || 0);
        tmpQ.fromArray(this.rotations, 4 * j);
        tmpS.copy(this.scales[n]);
        local = tmpM.compose(tmpT, tmpQ, tmpS);
      }
      const p = this.parent[n];
      if (p >= 0) this.world[n].multiplyMatrices(this.world[p], local);
      else this.world[n].copy(local);
    }
  }

  // Size and floor: characters whose height is not 0.5..3 units (a file in
  // centimetres) are scaled to 1.75 m (`scale`); the feet stand on y = 0.
  fit() {
    this.update();
    const box = new THREE.Box3();
    const p = new THREE.Vector3();
    for (const n of this.jointNodes) box.expandByPoint(p.setFromMatrixPosition(this.world[n]));
    const height = Math.max(box.max.y - Math.min(box.min.y, 0), 1e-6);
    this.scale = height < 0.5 || height > 3 ? 1.75 / height : 1;
    this.height = height * this.scale;
  }

  // World positions (after the view's scaling) of the hand joints.
  handPositions() {
    this.update();
    const p = new THREE.Vector3();
    return this.hands.map((j) => {
      p.setFromMatrixPosition(this.world[this.jointNodes[j]]).multiplyScalar(this.scale);
      return { joint: this.info.joints[j].name, x: +p.x.toFixed(4), y: +p.y.toFixed(4), z: +p.z.toFixed(4) };
    });
  }
}

// A character drawn in one WebGL context (each context needs its own
// buffers): meshes skinned by the vertex shader from `rig`'s pose.
export class CharacterModel {
  constructor(rig) {
    this.rig = rig;
    this.glb = rig.glb;
    this.info = rig.info;
    this.name = rig.name;
    this.jointNodes = rig.jointNodes;
    this.group = new THREE.Group();
    this.group.name = `character ${rig.name}`;
    this.group.scale.setScalar(rig.scale);
    this.group.updateMatrixWorld(true);
    this.skins = rig.skins.map((s) => ({ joints: s.joints, ibm: s.ibm }));
    this.onTexture = () => {};
    this.drawables = [];
    this.buildMeshes(this.glb);
    this.buildMouth();
    this.sync();
  }

  materialColor(index) {
    const m = (this.glb.json.materials || [])[index] || {};
    const pbr = m.pbrMetallicRoughness || {};
    return { color: pbr.baseColorFactor || [0.8, 0.8, 0.8, 1], texture: (pbr.baseColorTexture || {}).index };
  }

  buildMeshes(glb) {
    const { json } = glb;
    (json.nodes || []).forEach((node, n) => {
      if (node.mesh === undefined) return;
      const mesh = json.meshes[node.mesh];
      const skin = node.skin !== undefined ? this.skins[node.skin] : null;
      // A mesh without a skin rides on its own node: one "joint", identity bind.
      const target = skin || { joints: [n], ibm: new THREE.Matrix4().toArray(new Float32Array(16)) };
      if (!skin) this.skins.push(target);
      mesh.primitives.forEach((p, k) => {
        if ((p.mode ?? 4) !== 4 || p.attributes.POSITION === undefined) return;  // triangles only
        const geometry = new THREE.BufferGeometry();
        const position = readAccessor(glb, p.attributes.POSITION);
        const count = position.length / 3;
        geometry.setAttribute('position', new THREE.BufferAttribute(position, 3));
        if (p.attributes.NORMAL !== undefined) {
          geometry.setAttribute('normal', new THREE.BufferAttribute(readAccessor(glb, p.attributes.NORMAL), 3));
        }
        geometry.setAttribute('uv', new THREE.BufferAttribute(p.attributes.TEXCOORD_0 !== undefined
          ? readAccessor(glb, p.attributes.TEXCOORD_0) : new Float32Array(count * 2), 2));
        let joints, weights;
        if (skin && p.attributes.JOINTS_0 !== undefined && p.attributes.WEIGHTS_0 !== undefined) {
          joints = Float32Array.from(readAccessor(glb, p.attributes.JOINTS_0, true));
          weights = readAccessor(glb, p.attributes.WEIGHTS_0);
          for (let v = 0; v < count; ++v) {  // weights sum to 1 (exporters round)
            const s = weights[4 * v] + weights[4 * v + 1] + weights[4 * v + 2] + weights[4 * v + 3];
            for (let c = 0; c < 4; ++c) weights[4 * v + c] = s > 0 ? weights[4 * v + c] / s : (c === 0 ? 1 : 0);
            for (let c = 0; c < 4; ++c) {
              if (joints[4 * v + c] >= target.joints.length) throw new Error(`${glb.name}: meshes[${node.mesh}] names joint ${joints[4 * v + c]} of a ${target.joints.length}-joint skin`);
            }
          }
        } else {
          joints = new Float32Array(count * 4);
          weights = new Float32Array(count * 4);
          for (let v = 0; v < count; ++v) weights[4 * v] = 1;
        }
        geometry.setAttribute('skinJoint', new THREE.BufferAttribute(joints, 4));
        geometry.setAttribute('skinWeight', new THREE.BufferAttribute(weights, 4));
        if (p.indices !== undefined) geometry.setIndex(new THREE.BufferAttribute(readAccessor(glb, p.indices, true), 1));
        if (p.attributes.NORMAL === undefined) geometry.computeVertexNormals();
        const { color, texture } = this.materialColor(p.material);
        const material = skinMaterial(target.joints.length, color, texture !== undefined ? this.texture(texture) : null);
        const object = new THREE.Mesh(geometry, material);
        object.frustumCulled = false;  // moved by the shader
        object.name = `${mesh.name || 'mesh'}.${k}`;
        this.group.add(object);
        this.drawables.push({ object, skin: target, position, joints, weights, mesh: node.mesh });
      });
    });
  }

  // A baseColorTexture from the GLB's images (decoded by the browser).
  texture(index) {
    const { json, bin } = this.glb;
    const t = (json.textures || [])[index];
    const image = t && (json.images || [])[t.source];
    if (!image || image.bufferView === undefined || !bin) return null;
    const view = json.bufferViews[image.bufferView];
    const bytes = new Uint8Array(bin.buffer, bin.byteOffset + (view.byteOffset || 0), view.byteLength);
    const tex = new THREE.Texture();
    tex.flipY = false;
    tex.wrapS = tex.wrapT = THREE.RepeatWrapping;
    createImageBitmap(new Blob([bytes], { type: image.mimeType || 'image/png' }))
      .then((bitmap) => { tex.image = bitmap; tex.needsUpdate = true; this.dirty = true; this.onTexture(); })
      .catch(() => {});
    return tex;
  }

  // The mouth: an ellipse on the front of the face, bound to the head bone
  // in the skin of the mesh with most head-weighted vertices. Placed from
  // the rig (up = hips -> head, left = right -> left upper arm, forward =
  // left × up) and the head's vertices in that skin's bind space.
  buildMouth() {
    this.mouth = null;
    const head = (this.info.joints || []).findIndex((j) => j.role === 'head');
    const hips = (this.info.joints || []).findIndex((j) => j.role === 'hips');
    const arms = ['left_upper_arm', 'right_upper_arm'].map((r) => (this.info.joints || []).findIndex((j) => j.role === r));
    if (head < 0 || hips < 0 || arms.includes(-1)) return;
    let best = null;
    for (const d of this.drawables) {
      const k = d.skin.joints.indexOf(this.jointNodes[head]);
      if (k < 0) continue;
      const verts = [];
      for (let v = 0; v < d.position.length / 3; ++v) {
        if (d.joints[4 * v] === k && d.weights[4 * v] > 0.5) verts.push(v);
      }
      if (!best || verts.length > best.verts.length) best = { d, k, verts };
    }
    if (!best || best.verts.length < 8) return;
    const { d, k } = best;
    // A joint's bind position in the skin's space: the inverse of its inverse bind matrix.
    const bindPos = (node) => {
      const i = d.skin.joints.indexOf(node);
      if (i < 0) return null;
      return new THREE.Vector3().setFromMatrixPosition(new THREE.Matrix4().getInverse(
        new THREE.Matrix4().fromArray(d.skin.ibm, 16 * i)));
    };
    const pHead = bindPos(this.jointNodes[head]), pHips = bindPos(this.jointNodes[hips]);
    const pl = bindPos(this.jointNodes[arms[0]]), pr = bindPos(this.jointNodes[arms[1]]);
    if (!pHead || !pHips || !pl || !pr) return;
    const up = pHead.clone().sub(pHips).normalize();
    const left = pl.clone().sub(pr);
    left.sub(up.clone().multiplyScalar(left.dot(up))).normalize();
    const forward = new THREE.Vector3().crossVectors(left, up).normalize();
    const p = new THREE.Vector3();
    let lo = Infinity, hi = -Infinity, wide = 0;
    for (const v of best.verts) {
      p.fromArray(d.position, 3 * v).sub(pHead);
      lo = Math.min(lo, p.dot(up));
      hi = Math.max(hi, p.dot(up));
      wide = Math.max(wide, Math.abs(p.dot(left)));
    }
    const size = hi - lo;
    const level = lo + 0.3 * size;  // mouths sit about a third up from the chin
    let front = -Infinity;
    for (const v of best.verts) {
      p.fromArray(d.position, 3 * v).sub(pHead);
      if (Math.abs(p.dot(up) - level) < 0.06 * size && Math.abs(p.dot(left)) < 0.2 * wide) front = Math.max(front, p.dot(forward));
    }
    if (!isFinite(front)) return;
    const center = pHead.clone().addScaledVector(up, level).addScaledVector(forward, front + 0.004 * size);
    const n = MOUTH_SEGMENTS + 1;
    const geometry = new THREE.BufferGeometry();
    const position = new Float32Array(n * 3);
    const normal = new Float32Array(n * 3);
    for (let i = 0; i < n; ++i) forward.toArray(normal, 3 * i);
    const index = [];
    for (let i = 0; i < MOUTH_SEGMENTS; ++i) index.push(0, 1 + i, 1 + ((i + 1) % MOUTH_SEGMENTS));
    const joints = new Float32Array(n * 4).fill(k);
    const weights = new Float32Array(n * 4);
    for (let i = 0; i < n; ++i) weights[4 * i] = 1;
    geometry.setAttribute('position', new THREE.BufferAttribute(position, 3));
    geometry.setAttribute('normal', new THREE.BufferAttribute(normal, 3));
    geometry.setAttribute('uv', new THREE.BufferAttribute(new Float32Array(n * 2), 2));
    geometry.setAttribute('skinJoint', new THREE.BufferAttribute(joints, 4));
    geometry.setAttribute('skinWeight', new THREE.BufferAttribute(weights, 4));
    geometry.setIndex(index);
    const object = new THREE.Mesh(geometry, skinMaterial(d.skin.joints.length, [0.12, 0.015, 0.02, 1], null));
    object.frustumCulled = false;
    object.name = 'mouth';
    this.group.add(object);
    this.drawables.push({ object, skin: d.skin });
    this.mouth = { object, center, left, up, halfWidth: 0.16 * wide, height: 0.16 * size, open: -1, width: -1 };
    this.setMouth(0, 1);
  }

  // Opening 0 (closed: a thin line) .. 1 (wide open), width factor ~0.5..1.1.
  setMouth(open, width) {
    const m = this.mouth;
    if (!m || (Math.abs(open - m.open) < 1e-3 && Math.abs(width - m.width) < 1e-3)) return;
    m.open = open;
    m.width = width;
    const attr = m.object.geometry.attributes.position;
    const a = attr.array;
    const hw = m.halfWidth * width, hh = m.height * (0.06 + 0.5 * open);
    m.center.toArray(a, 0);
    for (let i = 0; i < MOUTH_SEGMENTS; ++i) {
      const t = (i / MOUTH_SEGMENTS) * 2 * Math.PI;
      tmpT.copy(m.center).addScaledVector(m.left, Math.cos(t) * hw).addScaledVector(m.up, Math.sin(t) * hh);
      tmpT.toArray(a, 3 * (i + 1));
    }
    attr.needsUpdate = true;
    this.dirty = true;
  }

  // The rig's current pose into every skin's joint matrices (jointWorld ·
  // inverseBind), the shaders' uniforms.
  sync() {
    const world = this.rig.world;
    this.rig.update();
    for (const skin of this.skins) {
      const buffer = skin.buffer || (skin.buffer = new Float32Array(skin.joints.length * 16));
      skin.joints.forEach((node, k) => {
        tmpM.fromArray(skin.ibm, 16 * k);
        tmpM.premultiply(world[node]);
        tmpM.toArray(buffer, 16 * k);
      });
    }
    for (const d of this.drawables) d.object.material.uniforms.jointMatrices.value = d.skin.buffer;
    this.dirty = true;
  }

  dispose() {
    for (const d of this.drawables) {
      d.object.geometry.dispose();
      d.object.material.dispose();
    }
  }
}

// A CharacterMotion message (proto JSON: bytes in base64) with its floats decoded.
export function decodeMotion(m) {
  const floats = (b64) => {
    const bin = atob(b64 || '');
    const bytes = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; ++i) bytes[i] = bin.charCodeAt(i);
    return new Float32Array(bytes.buffer, 0, bytes.length >> 2);
  };
  return {
    character: m.character, frameTimeS: m.frameTimeS || 1 / 30, startTimeS: m.startTimeS || 0, frames: m.frames || 0,
    rotations: floats(m.rotations), translations: floats(m.translations), rootScale: m.rootScale || 1,
  };
}
