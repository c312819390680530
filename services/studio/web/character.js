// kinemo studio: a glTF / VRM character, drawn by three.js.
//
// The studio (services/studio/core/character.h) retargets the motion onto
// the character's rig and sends, per frame, each joint node's local rotation
// and the hips' translation, and the weights of the character's face targets
// (CharacterMotion; the targets come once with CharacterInfo). The page
// only applies them:
//   - CharacterPose (the page's main thread): a pose and face weights,
//     blended between a motion's frames; no three.js objects.
//   - CharacterModel (the renderer, render.js, in its worker): the file read
//     by three.js' GLTFLoader (EXT_meshopt_compression with the meshopt
//     decoder, KHR_draco_mesh_compression with the Draco decoder served under
//     /libs/draco/, KHR_mesh_quantization, WebP textures) and, for VRM 0.x /
//     1.0, @pixiv/three-vrm's VRMLoaderPlugin; the pose set on the glTF nodes
//     (three's SkinnedMesh skins on the GPU), the face on the meshes' morph
//     targets by name, the VRM's expressions by name
//     (vrm.expressionManager.setValue) or the jaw bone.
import * as THREE from '/libs/kinemo-libs.js';

// A CharacterMotion message (proto JSON: bytes in base64) with its arrays decoded.
export function decodeMotion(m) {
  const bytes = (b64) => {
    const bin = atob(b64 || '');
    const out = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; ++i) out[i] = bin.charCodeAt(i);
    return out;
  };
  const floats = (b64) => {
    const b = bytes(b64);
    return new Float32Array(b.buffer, 0, b.length >> 2);
  };
  return {
    character: m.character, frameTimeS: m.frameTimeS || 1 / 30, startTimeS: m.startTimeS || 0, frames: m.frames || 0,
    rotations: floats(m.rotations), translations: floats(m.translations), rootScale: m.rootScale || 1,
    face: bytes(m.faceWeights),  // per frame per face target, 0..255
  };
}

// A character's pose and face on the page's main thread: what the renderer
// is sent. `info` is the studio's CharacterInfo.
export class CharacterPose {
  constructor(info) {
    this.info = info;
    this.name = info.name;
    this.joints = (info.joints || []).length;
    this.translated = (info.translatedJoints || []).length;
    this.faceTargets = (info.faceTargets || []).length;
    this.rotations = new Float32Array(this.joints * 4);
    this.translations = new Float32Array(this.translated * 3);
    this.face = new Float32Array(this.faceTargets);
    this.posed = false;  // false: the file's own rest pose (nothing sent yet)
  }

  // One frame of a decoded CharacterMotion; `alpha` blends towards frame
  // f + 1 (normalised lerp of the rotations, linear for the rest).
  setFrame(motion, f, alpha = 0) {
    const nj = this.joints, nt = this.translated, nf = this.faceTargets;
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
    if (nf > 0 && motion.face.length >= (f1 + 1) * nf) {
      for (let k = 0; k < nf; ++k) {
        this.face[k] = (motion.face[f0 * nf + k] * (1 - alpha) + motion.face[f1 * nf + k] * alpha) / 255;
      }
    }
    this.posed = true;
  }
}

// One DRACOLoader per renderer (its decoder runs in workers of its own).
let draco = null;
function dracoLoader() {
  if (!draco) {
    draco = new THREE.DRACOLoader();
    draco.setDecoderPath('/libs/draco/');
  }
  return draco;
}

// VRM 0.x blendShapeGroup presets -> the VRM 1.0 preset names three-vrm
// gives them.
const VRM0_PRESETS = {
  a: 'aa', i: 'ih', u: 'ou', e: 'ee', o: 'oh', blink: 'blink', blink_l: 'blinkLeft', blink_r: 'blinkRight',
  joy: 'happy', angry: 'angry', sorrow: 'sad', fun: 'relaxed', neutral: 'neutral', lookup: 'lookUp',
  lookdown: 'lookDown', lookleft: 'lookLeft', lookright: 'lookRight',
};

// Meshes with more triangles are simplified where WebGL runs in software.
const SIMPLIFY_ABOVE = 5000;

// FaceTarget.kind as the studio's JSON names it.
const MORPH = 'FACE_TARGET_KIND_MORPH', EXPRESSION = 'FACE_TARGET_KIND_EXPRESSION', JAW = 'FACE_TARGET_KIND_JAW_BONE';

// A character in one renderer: the loaded scene under a group that scales
// it to metres and turns a VRM 0.x (which faces -z) to face +z, as glTF
// characters do.
export class CharacterModel {
  // Resolves with the model; rejects naming the file. `software`: WebGL
  // runs in software (see lighten()).
  static async load(buffer, name, info, software = false) {
    const loader = new THREE.GLTFLoader();
    loader.setMeshoptDecoder(THREE.MeshoptDecoder);
    loader.setDRACOLoader(dracoLoader());
    loader.register((parser) => new THREE.VRMLoaderPlugin(parser));
    let gltf;
    try {
      gltf = await loader.parseAsync(buffer, '');
    } catch (err) {
      throw new Error(`${name}: ${err && err.message ? err.message : err}`);
    }
    const model = new CharacterModel(gltf, name, info);
    if (software) {
      await THREE.MeshoptSimplifier.ready;
      model.lighten();
    }
    return model;
  }

  constructor(gltf, name, info) {
    this.name = name;
    this.info = info;
    this.vrm = gltf.userData.vrm || null;
    this.root = this.vrm ? this.vrm.scene : gltf.scene;
    if (this.vrm) {
      // The studio poses the file's own nodes; three-vrm would copy its
      // normalised rig over them at each update.
      if (this.vrm.humanoid) this.vrm.humanoid.autoUpdateHumanBones = false;
      THREE.VRMUtils.rotateVRM0(this.vrm);  // VRM 0.x faces -z
    }
    this.group = new THREE.Group();
    this.group.name = `character ${name}`;
    this.group.add(this.root);
    // glTF node index -> three object.
    const byNode = [];
    this.root.traverse((o) => {
      const a = gltf.parser.associations.get(o);
      if (a && a.nodes !== undefined && byNode[a.nodes] === undefined) byNode[a.nodes] = o;
    });
    this.jointObjects = (info.joints || []).map((j, k) => {
      const o = byNode[j.node];
      if (!o) throw new Error(`${name}: joint ${j.name} (node ${j.node}) is not in the loaded scene`);
      return o;
    });
    this.bind = info.bindTranslations || [];
    this.translated = info.translatedJoints || [];
    this.translatedSlot = new Map(this.translated.map((j, t) => [j, t]));
    this.hands = ['left_hand', 'right_hand'].map((role) => (info.joints || []).findIndex((j) => j.role === role))
      .filter((j) => j >= 0);
    this.head = (info.joints || []).findIndex((j) => j.role === 'head');
    this.meshes = [];
    this.root.traverse((o) => {
      if (o.isMesh) {
        o.frustumCulled = false;  // skinned: the bounds of the bind pose say little
        this.meshes.push(o);
      }
    });
    this.bindFace(info.faceTargets || [], byNode);
    this.fit();
    this.measureHead();
    this.dirty = true;
  }

  // The head as its meshes have it, in the pose the file was loaded in: the
  // vertices skinned mostly to the head joint or below it (eyes, jaw,
  // teeth, hair). Their box's centre, kept in the head joint's frame, is
  // where the close-up camera looks; its height is the head's size (a
  // realistic head about 0.25 m, a cartoon one more). Without skinned head
  // vertices: the head joint and 0.25 m.
  measureHead() {
    this.headCentre = new THREE.Vector3();
    this.headSize = 0.25;
    if (this.head < 0) return;
    const headObj = this.jointObjects[this.head];
    const below = new Set();
    headObj.traverse((o) => below.add(o));
    this.group.updateMatrixWorld(true);
    const box = new THREE.Box3();
    const v = new THREE.Vector3();
    for (const mesh of this.meshes) {
      const g = mesh.geometry, pos = g.attributes.position, si = g.attributes.skinIndex, sw = g.attributes.skinWeight;
      if (!mesh.isSkinnedMesh || !pos || !si || !sw) continue;
      const bones = mesh.skeleton.bones;
      const step = Math.max(1, Math.floor(pos.count / 20000));
      for (let i = 0; i < pos.count; i += step) {
        const w = [sw.getX(i), sw.getY(i), sw.getZ(i), sw.getW(i)];
        const b = [si.getX(i), si.getY(i), si.getZ(i), si.getW(i)];
        let k = 0;
        for (let c = 1; c < 4; ++c) if (w[c] > w[k]) k = c;
        if (!(w[k] > 0) || !below.has(bones[b[k]])) continue;
        // Skinned as drawn (a quantized skinned mesh keeps its scale in the
        // inverse bind matrices, not in the node).
        box.expandByPoint(mesh.applyBoneTransform(i, v.fromBufferAttribute(pos, i)).applyMatrix4(mesh.matrixWorld));
      }
    }
    if (box.isEmpty()) return;
    this.headSize = Math.max(box.max.y - box.min.y, 0.05);
    this.headCentre = headObj.worldToLocal(box.getCenter(v).clone());
  }

  // Where WebGL runs in software (SwiftShader, llvmpipe) every pixel's
  // shading is CPU time: physically based and MToon (VRM's toon shader)
  // materials become Lambert ones (same colour, texture, alpha; skinning and
  // morph targets as before) and MToon's outline pass (each outlined mesh
  // drawn twice) is left out.
  lighten() {
    for (const mesh of this.meshes) {
      const materials = Array.isArray(mesh.material) ? mesh.material : [mesh.material];
      const lighter = materials.map((m) => {
        if (m.isOutline) {
          m.visible = false;
          return m;
        }
        if (!m.isMeshStandardMaterial && !m.isMToonMaterial) return m;
        const l = new THREE.MeshLambertMaterial({
          name: m.name, color: m.color, map: m.map, transparent: m.transparent, opacity: m.opacity,
          alphaTest: m.alphaTest, side: m.side, vertexColors: m.vertexColors,
        });
        if (m.isMeshStandardMaterial) {
          l.emissive.copy(m.emissive);
          l.emissiveMap = m.emissiveMap;
        }
        m.dispose();
        return l;
      });
      mesh.material = Array.isArray(mesh.material) ? lighter : lighter[0];
      this.simplify(mesh);
      this.morphOnCpu(mesh);
    }
  }

  // Software rasterisers pay per triangle: a mesh of more than
  // SIMPLIFY_ABOVE triangles is simplified (meshoptimizer's simplifier, as
  // three ships it) to a quarter, keeping every vertex a morph target moves
  // (the face: lips, eyelids, brows stay as modelled; not in a mesh whose
  // morphs move most of it, see below) and the mesh's borders. Only the index buffer changes: the kept vertices, their skin
  // weights, UVs and morph deltas are the file's.
  simplify(mesh) {
    const g = mesh.geometry;
    if (!g.index || g.index.count / 3 <= SIMPLIFY_ABOVE || g.groups.length > 1) return;
    const pos = g.attributes.position, n = pos.count;
    const positions = new Float32Array(n * 3);
    for (let i = 0; i < n; ++i) {
      positions[3 * i] = pos.getX(i);
      positions[3 * i + 1] = pos.getY(i);
      positions[3 * i + 2] = pos.getZ(i);
    }
    let lock = new Uint8Array(n), locked = 0;
    for (const t of (g.morphAttributes && g.morphAttributes.position) || []) {
      for (let i = 0; i < n; ++i) {
        if (!lock[i] && (t.getX(i) !== 0 || t.getY(i) !== 0 || t.getZ(i) !== 0)) {
          lock[i] = 1;
          ++locked;
        }
      }
    }
    // Morphs that move most of a mesh move a part as a whole (the VALID
    // man's lower teeth: 31 teeth morphs move all 4737 vertices with the
    // jaw); locking them all kept the teeth's 8176 triangles, 38 % of the
    // drawn ones, inside the mouth. Such a mesh is simplified like the rest:
    // its kept vertices still move by their own morph deltas.
    if (locked > n / 2) lock = new Uint8Array(n);
    const normal = g.attributes.normal;
    const attributes = new Float32Array(n * 3);
    if (normal) for (let i = 0; i < n; ++i) {
      attributes[3 * i] = normal.getX(i);
      attributes[3 * i + 1] = normal.getY(i);
      attributes[3 * i + 2] = normal.getZ(i);
    }
    const index = Uint32Array.from(g.index.array);
    const target = Math.floor(index.length / 4 / 3) * 3;
    const [simplified] = THREE.MeshoptSimplifier.simplifyWithAttributes(
      index, positions, 3, attributes, 3, [0.5, 0.5, 0.5], lock, target, 0.02, ['LockBorder']);
    if (simplified.length >= index.length) return;
    this.simplified = (this.simplified || 0) + (index.length - simplified.length) / 3;
    g.setIndex(new THREE.BufferAttribute(simplified, 1));
  }

  // Morph targets summed here instead of in the vertex shader: three's
  // shader loops over every target of the mesh for every vertex (the VALID
  // head has 65 of them on 22 k vertices), which in software WebGL halved
  // the frame rate; a face moves a few targets at a time, each touching a
  // few thousand vertices. The mesh keeps its morphTargetInfluences and
  // dictionary (set by setFace and by three-vrm's expressions) and
  // update() writes base + Σ wᵢ·Δᵢ into its positions (normals stay).
  morphOnCpu(mesh) {
    const g = mesh.geometry;
    const targets = g.morphAttributes && g.morphAttributes.position;
    if (!targets || targets.length === 0 || !mesh.morphTargetInfluences) return;
    const pos = g.attributes.position;
    const n = pos.count;
    const base = new Float32Array(n * 3);
    for (let i = 0; i < n; ++i) {
      base[3 * i] = pos.getX(i);
      base[3 * i + 1] = pos.getY(i);
      base[3 * i + 2] = pos.getZ(i);
    }
    const relative = g.morphTargetsRelative;
    const deltas = targets.map((t) => {
      const index = [], delta = [];
      for (let i = 0; i < n; ++i) {
        let dx = t.getX(i), dy = t.getY(i), dz = t.getZ(i);
        if (!relative) {
          dx -= base[3 * i];
          dy -= base[3 * i + 1];
          dz -= base[3 * i + 2];
        }
        if (dx !== 0 || dy !== 0 || dz !== 0) {
          index.push(i);
          delta.push(dx, dy, dz);
        }
      }
      return { index: Uint32Array.from(index), delta: Float32Array.from(delta) };
    });
    const attribute = new THREE.BufferAttribute(base.slice(), 3);
    g.setAttribute('position', attribute);
    g.morphAttributes = {};
    const influences = mesh.morphTargetInfluences;
    (this.cpuMorphs || (this.cpuMorphs = [])).push({ mesh, base, deltas, attribute, influences, applied: new Float32Array(influences.length) });
  }

  applyCpuMorphs() {
    for (const m of this.cpuMorphs || []) {
      let changed = false;
      for (let k = 0; k < m.influences.length; ++k) if (m.influences[k] !== m.applied[k]) changed = true;
      if (!changed) continue;
      const out = m.attribute.array;
      out.set(m.base);
      for (let k = 0; k < m.influences.length; ++k) {
        const w = m.influences[k];
        m.applied[k] = w;
        if (w === 0) continue;
        const { index, delta } = m.deltas[k];
        for (let j = 0; j < index.length; ++j) {
          const o = 3 * index[j];
          out[o] += w * delta[3 * j];
          out[o + 1] += w * delta[3 * j + 1];
          out[o + 2] += w * delta[3 * j + 2];
        }
      }
      m.attribute.needsUpdate = true;
    }
  }

  // The face targets the studio drives, resolved to what they move here.
  bindFace(targets, byNode) {
    this.face = targets.map((t) => {
      const kind = t.kind || '';
      if (kind === MORPH) {
        const slots = [];
        for (const m of this.meshes) {
          const k = m.morphTargetDictionary ? m.morphTargetDictionary[t.name] : undefined;
          if (k !== undefined) slots.push([m.morphTargetInfluences, k]);
        }
        return { kind, name: t.name, channel: t.channel || '', slots };
      }
      if (kind === EXPRESSION) {
        // A VRM 0.x preset by its 0.x name ("a", "blink_l", "joy"): three-vrm
        // names the loaded expression by its 1.0 preset ("aa", "blinkLeft", "happy").
        const manager = this.vrm && this.vrm.expressionManager;
        let name = t.name;
        if (manager && !manager.getExpression(name) && VRM0_PRESETS[name.toLowerCase()]) name = VRM0_PRESETS[name.toLowerCase()];
        return { kind, name, channel: t.channel || '', ok: Boolean(manager && manager.getExpression(name)) };
      }
      if (kind === JAW) {
        const o = byNode[t.node];
        const axis = new THREE.Vector3(...(t.axis && t.axis.length === 3 ? t.axis : [1, 0, 0])).normalize();
        return { kind, name: t.name, channel: t.channel || '', object: o, axis, maxRad: (t.maxDeg || 0) * Math.PI / 180,
                 base: o ? o.quaternion.clone() : null, joint: o ? this.jointObjects.indexOf(o) : -1 };
      }
      return { kind, name: t.name, channel: t.channel || '' };
    });
    this.faceWeights = new Float32Array(this.face.length);
  }

  // Size and floor: characters whose height is not 0.5..3 units (a file in
  // centimetres) are scaled to 1.75 m; the joints of the rest pose give the
  // height, with the feet on y = 0.
  fit() {
    this.group.updateMatrixWorld(true);
    const box = new THREE.Box3();
    const p = new THREE.Vector3();
    for (const o of this.jointObjects) box.expandByPoint(o.getWorldPosition(p));
    if (box.isEmpty()) box.setFromObject(this.root);  // no joints named: the meshes' bounds
    const height = Math.max(box.max.y - Math.min(box.min.y, 0), 1e-6);
    this.scale = height < 0.5 || height > 3 ? 1.75 / height : 1;
    this.height = height * this.scale;
    this.group.scale.setScalar(this.scale);
  }

  // The pose (CharacterPose's arrays) onto the joints' nodes.
  setPose(rotations, translations) {
    this.jointObjects.forEach((o, j) => {
      o.quaternion.fromArray(rotations, 4 * j);
      const t = this.translatedSlot.get(j);
      if (t !== undefined) o.position.fromArray(translations, 3 * t);
      else if (this.bind.length >= 3 * j + 3) o.position.set(this.bind[3 * j], this.bind[3 * j + 1], this.bind[3 * j + 2]);
    });
    for (const f of this.face) if (f.kind === JAW && f.joint >= 0) f.base.copy(f.object.quaternion);
    this.dirty = true;
  }

  // The face targets' weights (0..1, in CharacterInfo.face_targets order).
  setFace(weights) {
    if (!weights || weights.length !== this.face.length) return;
    this.face.forEach((f, k) => {
      const w = weights[k];
      this.faceWeights[k] = w;
      if (f.kind === MORPH) {
        for (const [influences, i] of f.slots) influences[i] = w;
      } else if (f.kind === EXPRESSION && f.ok) {
        this.vrm.expressionManager.setValue(f.name, w);
      }
    });
    this.dirty = true;
  }

  // Before drawing: the jaw bone turned from its pose by its weight, and a
  // VRM's expressions, look-at and spring bones (`dt` seconds since the
  // last draw).
  update(dt, camera) {
    this.face.forEach((f, k) => {
      if (f.kind === JAW && f.object) {
        f.object.quaternion.setFromAxisAngle(f.axis, this.faceWeights[k] * f.maxRad).premultiply(f.base);
      }
    });
    if (this.vrm) {
      if (this.vrm.lookAt && camera) this.vrm.lookAt.target = camera;
      this.vrm.update(Math.min(Math.max(dt, 0), 0.1));
    }
    this.applyCpuMorphs();
  }

  // World positions of the hand joints as drawn.
  handPositions() {
    const p = new THREE.Vector3();
    return this.hands.map((j) => {
      this.jointObjects[j].getWorldPosition(p);
      return { joint: this.info.joints[j].name, x: +p.x.toFixed(4), y: +p.y.toFixed(4), z: +p.z.toFixed(4) };
    });
  }

  // Where the head is as drawn (for the close-up camera): its meshes'
  // centre (measureHead) and size in metres; null without a head joint.
  facePosition() {
    if (this.head < 0) return null;
    const p = this.jointObjects[this.head].localToWorld(this.headCentre.clone());
    return { x: +p.x.toFixed(4), y: +p.y.toFixed(4), z: +p.z.toFixed(4), size: +this.headSize.toFixed(3) };
  }

  // What the face shows now: each target's weight by name, and how many
  // morph targets / expressions it moves.
  faceState() {
    const weights = {}, channels = {};
    let moved = 0;
    this.face.forEach((f, k) => {
      weights[f.name] = +this.faceWeights[k].toFixed(3);
      channels[f.name] = f.channel;
      if ((f.kind === MORPH && f.slots.length > 0) || (f.kind === EXPRESSION && f.ok) || (f.kind === JAW && f.object)) ++moved;
    });
    return { weights, channels, bound: moved };
  }

  drawables() {
    return this.meshes.length;
  }

  // A VRM's own credit line from its meta (VRM 1.0: name, authors,
  // licenseUrl; 0.x: title, author, licenseName / otherLicenseUrl); '' for
  // glTF files, whose asset block rarely names one.
  credit() {
    const m = this.vrm && this.vrm.meta;
    if (!m) return '';
    const title = m.name || m.title || '';
    const authors = Array.isArray(m.authors) ? m.authors.join(', ') : m.author || '';
    const licence = m.licenseUrl || m.otherLicenseUrl || m.licenseName || '';
    return [title && `"${title}"`, authors && `by ${authors}`, licence && `(${licence})`].filter(Boolean).join(' ');
  }

  dispose() {
    this.root.traverse((o) => {
      if (o.geometry) o.geometry.dispose();
      const mats = Array.isArray(o.material) ? o.material : o.material ? [o.material] : [];
      for (const m of mats) {
        for (const v of Object.values(m)) if (v && v.isTexture) v.dispose();
        m.dispose();
      }
    });
    if (this.vrm) THREE.VRMUtils.deepDispose(this.root);
  }
}
