// kinemo studio: the page's own code. Talks to the studio over one
// WebSocket (/ws) in the JSON of kinemo.studio.v1.ClientMessage /
// ServerMessage (proto/kinemo/studio/v1/studio.proto), draws the character
// with three.js and @pixiv/three-vrm (from npm, bundled by the build into
// /libs/kinemo-libs.js), the timeline on a 2D canvas, and exposes
// window.kinemoStudio for tests and curious people.
import * as THREE from '/libs/kinemo-libs.js';
import { CharacterPose, decodeMotion } from '/static/character.js';

const { OrbitControls, BVHLoader } = THREE;

const $ = (id) => document.getElementById(id);
const CHUNK_S = 0.02;          // live: 20 ms chunks
const LIVE_RATE_HZ = 16000;    // live: 16 kHz mono S16LE
const CLOSE_UP_HEADS = 2.6;    // the face close-up: camera to face, in head sizes
const VISEMES = ['PAU', 'R', 'K_G_NG', 'AA', 'F_V', 'CH_SH_JH', 'AO', 'OW', 'N_D_T_L', 'EY', 'TH_DH',
                 'S_Z_ZH', 'B_P_M', 'HH', 'W_UW'];

// ---------------------------------------------------------------- socket

// One WebSocket; calls by id. call() resolves with the answer of a unary
// call; open() registers a handler for every message of a stream or watch.
class Socket {
  constructor(url) {
    this.url = url;
    this.nextId = 1;
    this.handlers = new Map();
    this.ready = new Promise((resolve) => { this.resolveReady = resolve; });
    this.onState = () => {};
    this.onCubeAr = () => {};
    this.connect();
  }
  connect() {
    this.ws = new WebSocket(this.url);
    this.ws.onmessage = (e) => this.receive(JSON.parse(e.data));
    this.ws.onclose = () => {
      this.onState(false, 'disconnected; retrying…');
      for (const h of this.handlers.values()) h({ error: { code: 'UNAVAILABLE', message: 'socket closed' } });
      this.handlers.clear();
      this.ready = new Promise((resolve) => { this.resolveReady = resolve; });
      setTimeout(() => this.connect(), 1000);
    };
  }
  receive(m) {
    if (m.hello) {
      this.hello = m.hello;
      this.onState(true, `connected to ${m.hello.coordinator} (kinemo ${m.hello.version})`);
      this.resolveReady();
      return;
    }
    // The AR view of an attached cube video follows its attach's answer
    // (same id, whose call has ended).
    if (m.cubeArVideo) { this.onCubeAr(m.cubeArVideo); return; }
    const h = this.handlers.get(m.id || 0);
    if (h) h(m);
    else if (m.error) console.warn('studio error', m.error.code, m.error.message);
  }
  send(message) { this.ws.send(JSON.stringify(message)); }
  // A unary call: resolves with the answer's body, rejects with the error.
  async call(name, body) {
    await this.ready;
    const id = this.nextId++;
    return new Promise((resolve, reject) => {
      this.handlers.set(id, (m) => {
        this.handlers.delete(id);
        if (m.error) reject(new Error(`${m.error.code}: ${m.error.message}`));
        else resolve(m[Object.keys(m).find((k) => k !== 'id')]);
      });
      this.send({ id, [name]: body });
    });
  }
  // A stream or watch: `onMessage` sees every message until `ended` or
  // `error` (both included). Returns the call's id.
  async open(name, body, onMessage) {
    await this.ready;
    const id = this.nextId++;
    this.handlers.set(id, (m) => {
      if (m.ended || m.error) this.handlers.delete(id);
      onMessage(m);
    });
    this.send({ id, [name]: body });
    return id;
  }
}

// ---------------------------------------------------------------- base64, WAV

function bytesToBase64(bytes) {
  let s = '';
  for (let i = 0; i < bytes.length; i += 0x8000) s += String.fromCharCode.apply(null, bytes.subarray(i, i + 0x8000));
  return btoa(s);
}
function base64ToText(b64) {
  const bin = atob(b64);
  const bytes = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; ++i) bytes[i] = bin.charCodeAt(i);
  return new TextDecoder().decode(bytes);
}

// ---------------------------------------------------------------- skeleton view

// Joints the stick figure leaves out (drawn by the hand's sphere or not at all).
const DETAIL_JOINT = /thumb|index|middle|ring|pinky|finger|eye|jaw/i;
const UP = new THREE.Vector3(0, 1, 0);
// Whether WebGL runs in software (headless Chromium's SwiftShader, Mesa's
// llvmpipe).
const GL_INFO = (() => {
  try {
    const gl = document.createElement('canvas').getContext('webgl');
    if (!gl) return { software: false };
    const info = gl.getExtension('WEBGL_debug_renderer_info');
    const name = info ? gl.getParameter(info.UNMASKED_RENDERER_WEBGL) : '';
    if (gl.getExtension('WEBGL_lose_context')) gl.getExtension('WEBGL_lose_context').loseContext();
    return { software: /swiftshader|llvmpipe|software/i.test(String(name)) };
  } catch (e) {
    return { software: false };
  }
})();

// The views' drawing (render.js): in a worker on OffscreenCanvases, or on
// this thread where the browser has no OffscreenCanvas.
class Renderer {
  constructor() {
    this.views = [];
    this.onRendered = () => {};
    this.nextId = 1;
    this.calls = new Map();
    const answer = (m) => {
      if (m.type === 'rendered') {
        this.views[m.view].rendered(m.at - performance.timeOrigin, m.lagRef, m);
        this.onRendered();
      } else if (this.calls.has(m.id)) {
        this.calls.get(m.id)(m);
        this.calls.delete(m.id);
      } else if (m.error) {
        console.warn('studio renderer', m.type, m.error);
      }
    };
    this.offscreen = 'transferControlToOffscreen' in HTMLCanvasElement.prototype;
    if (this.offscreen) {
      this.worker = new Worker('/static/render-worker.js', { type: 'module' });
      this.worker.onmessage = (e) => answer(e.data);
      this.worker.onerror = (e) => console.warn('studio renderer failed', e.message);
      this.post = (m, transfer) => this.worker.postMessage(m, transfer || []);
    } else {
      const host = import('/static/render.js').then(({ createRenderHost }) =>
        createRenderHost((m) => answer(m), (f) => requestAnimationFrame(f)));
      this.post = (m) => host.then((handle) => handle(m));
    }
  }
  add(view, canvas) {
    const index = this.views.push(view) - 1;
    const target = this.offscreen ? canvas.transferControlToOffscreen() : canvas;
    this.post({ type: 'init', view: index, canvas: target, software: GL_INFO.software },
              this.offscreen ? [target] : []);
    return index;
  }
  // A message answered by the renderer: resolves with the answer, rejects with its error.
  call(m) {
    const id = this.nextId++;
    return new Promise((resolve, reject) => {
      this.calls.set(id, (a) => (a.error ? reject(new Error(a.error)) : resolve(a)));
      this.post({ ...m, id });
    });
  }
}
const renderer = new Renderer();

// One 3D view: a skeleton drawn as shaded capsules and/or the skinned
// character, over a floor grid, with an orbit camera. The bones come from
// BVHLoader (files) or from a live stream's header. This thread poses; the
// renderer (render.js) draws the latest pose once per animation frame.
class SkeletonView {
  constructor(figure) {
    this.figure = figure;
    this.canvas = figure.querySelector('canvas');
    this.caption = figure.querySelector('.clip-name');
    this.camera = new THREE.PerspectiveCamera(40, 1, 0.05, 100);
    this.camera.position.set(1.3, 1.3, 3.3);
    this.controls = new OrbitControls(this.camera, this.canvas);
    this.controls.target.set(0, 0.9, 0);
    this.controls.update();
    this.dirty = true;              // send a frame only when something moved
    this.controls.addEventListener('change', () => { this.dirty = true; });
    this.root = new THREE.Group();   // scaled to metres
    this.bones = [];
    this.segments = [];              // {parent, child}
    this.jointBones = [];            // bones drawn as a sphere
    this.jointPositions = new Float32Array(0);
    this.segmentPoses = new Float32Array(0);  // per segment: position, quaternion, length
    this.hands = [];
    this.mixer = null;
    this.duration = 0;
    this.time = -1;
    this.character = null;         // CharacterPose: the pose and face of the drawn character
    this.characterDrawn = null;    // {name, drawables, height} as the renderer built it
    this.characterMotion = null;   // decoded CharacterMotion of the clip
    this.poseChanged = false;
    this.drawnState = null;        // the renderer's last drawn frame: {time, hands, face}
    this.showStick = false;
    this.closeUp = false;          // the face close-up camera (setCloseUp)
    this.bodyView = null;          // the camera before the close-up
    this.faceAt = null;            // the face position the close-up last followed
    this.renders = [];             // times of the last second's renders
    this.lagRef = 0;               // send time (epoch ms) of the chunk of the newest live frame
    this.inFlight = 0;             // when the frame the renderer is drawing was sent (0: none)
    this.size = { width: 0, height: 0 };
    this.index = renderer.add(this, this.canvas);
  }

  // The character (or null for the stick figure only); resolves once the
  // renderer has built its meshes.
  async setCharacter(info, bytes) {
    this.character = null;
    this.characterDrawn = null;
    this.characterMotion = null;
    this.drawnState = null;
    if (info) this.character = new CharacterPose(info);
    const rig = this.character;
    this.applyVisibility();
    try {
      const built = await renderer.call({ type: 'character', view: this.index, glb: info ? bytes : null,
                                          name: info ? info.name : '', info: info || null });
      if (this.character === rig && rig) {
        this.characterDrawn = { name: rig.name, drawables: built.drawables, height: built.height, credit: built.credit };
      }
    } catch (err) {
      if (this.character === rig) this.character = null;
      this.applyVisibility();
      throw err;
    }
  }

  setCharacterMotion(motion) {
    this.characterMotion = motion;
    const t = this.time;
    this.time = -1;
    this.setTime(Math.max(t, 0));
  }

  applyVisibility() {
    this.dirty = true;
  }
  stickVisible() { return this.showStick || !this.character; }

  // The character at time t: its motion's frames (blended), body and face.
  poseCharacter(t) {
    const c = this.character;
    if (!c) return;
    const m = this.characterMotion;
    if (m && m.frames > 0) {
      const x = Math.max((t - m.startTimeS) / m.frameTimeS, 0);
      const f = Math.floor(x);
      c.setFrame(m, f, Math.min(x - f, 1));
      this.poseChanged = true;
    }
    this.dirty = true;
  }

  clear() {
    while (this.root.children.length > 0) this.root.remove(this.root.children[0]);
    this.bones = [];
    this.segments = [];
    this.jointBones = [];
    this.hands = [];
    this.mixer = null;
    this.duration = 0;
    this.time = -1;
    this.characterMotion = null;
  }

  // The stick figure for `bones` (bones[0] the root; parents first).
  setBones(bones, name) {
    this.clear();
    this.bones = bones;
    this.root.add(bones[0]);
    this.root.updateMatrixWorld(true);
    const hands = [];
    for (const b of bones) {
      const isHand = /hand|wrist/i.test(b.name) && !/thumb|index|middle|ring|pinky|finger/i.test(b.name);
      if (isHand) this.hands.push(b);
      // Fingers, eyes and jaw (SMPL-X has 33 of them) are not drawn: at the
      // stick figure's thickness they are blobs, and each is a draw call (the
      // 55-joint figure drew 110 meshes, too slow for software rendering).
      if (DETAIL_JOINT.test(b.name)) continue;
      this.jointBones.push(b);
      hands.push(isHand ? 1 : 0);
      if (b.parent && b.parent.isBone && b.position.lengthSq() > 0) this.segments.push({ parent: b.parent, child: b });
    }
    this.jointPositions = new Float32Array(3 * this.jointBones.length);
    this.segmentPoses = new Float32Array(8 * this.segments.length);
    renderer.post({ type: 'stick', view: this.index, hands: Uint8Array.from(hands), segments: this.segments.length });
    this.fit();
    this.caption.textContent = name;
    this.applyVisibility();
  }

  // Scales the figure to metres from its current pose's height (BVH does not
  // say its unit) and stands it on the floor.
  fit() {
    this.root.scale.setScalar(1);
    this.root.position.set(0, 0, 0);
    this.root.updateMatrixWorld(true);
    const box = new THREE.Box3();
    const p = new THREE.Vector3();
    for (const b of this.bones) box.expandByPoint(b.getWorldPosition(p));
    const height = Math.max(box.max.y - box.min.y, 1e-6);
    const scale = 1.7 / height;
    this.root.scale.setScalar(scale);
    const center = box.getCenter(p);
    this.root.position.set(-center.x * scale, -box.min.y * scale, -center.z * scale);
    this.updateMeshes();
  }

  // BVH text → bones and an animation clip (BVHLoader).
  loadBvh(text, name, faceTrack = null) {
    const result = new BVHLoader().parse(text);
    this.bvhText = text;
    this.faceTrack = faceTrack;   // a recording's face (FaceTrack JSON), or null
    this.setBones(result.skeleton.bones, name);
    // The clip's tracks name `.bones[<name>]`: the mixer's root holds the skeleton.
    const holder = new THREE.Object3D();
    holder.skeleton = result.skeleton;
    this.mixer = new THREE.AnimationMixer(holder);
    this.mixer.clipAction(result.clip).play();
    this.duration = result.clip.duration;
    this.setTime(0);
    this.fit();
  }

  setTime(t) {
    if (t === this.time) return;
    this.time = t;
    if (this.mixer) {
      this.mixer.setTime(Math.min(Math.max(t, 0), this.duration));
      this.updateMeshes();
    }
    this.poseCharacter(t);
  }

  // The stick figure's spheres and capsules from the bones' world positions.
  updateMeshes() {
    this.dirty = true;
    this.root.updateMatrixWorld(true);
    const a = new THREE.Vector3(), b = new THREE.Vector3(), d = new THREE.Vector3(), q = new THREE.Quaternion();
    this.jointBones.forEach((bone, i) => bone.getWorldPosition(a).toArray(this.jointPositions, 3 * i));
    this.segments.forEach((s, i) => {
      s.parent.getWorldPosition(a);
      s.child.getWorldPosition(b);
      d.subVectors(b, a);
      const length = d.length();
      const o = 8 * i;
      a.toArray(this.segmentPoses, o);
      if (length > 1e-9) q.setFromUnitVectors(UP, d.divideScalar(length)).toArray(this.segmentPoses, o + 3);
      else q.set(0, 0, 0, 1).toArray(this.segmentPoses, o + 3);
      this.segmentPoses[o + 7] = Math.max(length, 1e-6);
    });
  }

  handPositions() {
    const p = new THREE.Vector3();
    return this.hands.map((h) => {
      h.getWorldPosition(p);
      return { joint: h.name, x: +p.x.toFixed(4), y: +p.y.toFixed(4), z: +p.z.toFixed(4) };
    });
  }

  // Whether the renderer is still drawing the last frame sent (a lost
  // answer is given up after 250 ms).
  busy() { return this.inFlight > 0 && performance.now() - this.inFlight < 250; }

  // The view's latest state to the renderer, if anything changed and the
  // renderer is done with the previous one (one frame in flight: when
  // drawing is slow, the page skips poses rather than queueing them).
  render() {
    const w = this.canvas.clientWidth, h = this.canvas.clientHeight;
    if (w === 0 || h === 0) return;
    if (w !== this.size.width || h !== this.size.height) {
      this.size = { width: w, height: h };
      renderer.post({ type: 'size', view: this.index, width: w, height: h,
                      pixelRatio: Math.min(window.devicePixelRatio, 2) });
      this.camera.aspect = w / h;
      this.camera.updateProjectionMatrix();
      this.dirty = true;
    }
    if (!this.dirty || this.busy()) return;
    this.dirty = false;
    this.inFlight = performance.now();
    const c = this.camera;
    const frame = {
      type: 'frame', view: this.index,
      camera: [c.position.x, c.position.y, c.position.z, c.quaternion.x, c.quaternion.y, c.quaternion.z, c.quaternion.w, c.fov],
      stick: this.stickVisible(), joints: this.jointPositions, segments: this.segmentPoses,
      character: Boolean(this.character) && !this.showStick, time: this.time, lagRef: this.lagRef,
    };
    if (this.character && this.character.posed && this.poseChanged) {
      frame.pose = { rotations: this.character.rotations, translations: this.character.translations };
      if (this.character.faceTargets > 0) frame.face = this.character.face;
    }
    this.poseChanged = false;
    this.lagRef = 0;
    renderer.post(frame);
  }

  // The renderer drew a frame at `at` (this page's performance.now() time);
  // `drawn` says what it showed (render.js).
  rendered(at, lagRef, drawn) {
    this.inFlight = 0;
    this.drawnState = { time: drawn.time, hands: drawn.hands || [], face: drawn.face || null, head: drawn.head || null };
    if (this.closeUp) this.followFace(drawn.head || null);
    if (this.onDrawn) this.onDrawn(at);
    this.renders.push(at);
    if (lagRef) state.shownLags.push(at - (lagRef - performance.timeOrigin));
    while (this.renders.length > 0 && this.renders[0] < at - 1000) this.renders.shift();
  }

  // The face close-up: the camera CLOSE_UP_HEADS head sizes (0.65 m for a
  // realistic head) in front of the character's face, seen from where the
  // user's orbit camera looked; then it follows the head as the body moves,
  // and orbit and zoom still work around the face. Off: the body view as it
  // was.
  setCloseUp(on) {
    if (on === this.closeUp) return;
    this.closeUp = on;
    if (on) {
      this.bodyView = { position: this.camera.position.clone(), target: this.controls.target.clone() };
      this.faceAt = null;
      if (this.drawnState && this.drawnState.head) this.followFace(this.drawnState.head);
    } else if (this.bodyView) {
      this.camera.position.copy(this.bodyView.position);
      this.controls.target.copy(this.bodyView.target);
      this.controls.update();
      this.faceAt = null;
    }
    this.dirty = true;
  }

  followFace(head) {
    if (!head) return;
    const at = new THREE.Vector3(head.x, head.y, head.z);
    if (!this.faceAt) {
      const dir = this.camera.position.clone().sub(this.controls.target);
      dir.y = 0;
      if (dir.lengthSq() < 1e-6) dir.set(0, 0, 1);
      dir.normalize().multiplyScalar(Math.min(Math.max(CLOSE_UP_HEADS * (head.size || 0.25), 0.3), 2));
      this.controls.target.copy(at);
      this.camera.position.copy(at).add(dir);
    } else {
      const moved = at.clone().sub(this.faceAt);
      if (moved.lengthSq() < 1e-10) return;
      this.controls.target.add(moved);
      this.camera.position.add(moved);
    }
    this.faceAt = at;
    this.controls.update();
    this.dirty = true;
  }

  // How far the camera is from the face (metres), or null: for tests.
  faceDistance() {
    const h = this.drawnState && this.drawnState.head;
    return h ? +this.camera.position.distanceTo(new THREE.Vector3(h.x, h.y, h.z)).toFixed(3) : null;
  }

  // Frames rendered in the last second (while something moves; 0 when still).
  renderFps() {
    const now = performance.now();
    while (this.renders.length > 0 && this.renders[0] < now - 1000) this.renders.shift();
    return this.renders.length;
  }

  // The character's hand joints and face as the renderer last drew them.
  characterHands() { return this.character && this.drawnState ? this.drawnState.hands : []; }
  characterFace() { return this.character && this.drawnState ? this.drawnState.face : null; }

  // Whether the character is drawn skinned now.
  skinned() {
    const d = this.characterDrawn;
    return Boolean(this.character && !this.showStick && d && d.name === this.character.name && d.drawables > 0);
  }
}

// A live stream's skeleton (kinemo.common.v1.Skeleton JSON) → bones; frames
// (MotionFrame.values, BVH channel order) are applied by applyFrame as BVH
// defines them: positions add to the offset, rotations compose in the
// listed order.
function bonesFromSkeleton(skeleton) {
  const bones = [];
  for (const j of skeleton.joints) {
    const b = new THREE.Bone();
    b.name = j.name;
    const o = j.offset || {};
    b.position.set(o.x || 0, o.y || 0, o.z || 0);
    b.userData.offset = b.position.clone();
    b.userData.channels = (j.channels || []).map((c) => c.replace('CHANNEL_', ''));
    const parent = j.parentIndex ?? -1;
    if (parent >= 0) bones[parent].add(b);
    bones.push(b);
    if (j.hasEndSite && j.endSiteOffset) {
      const end = new THREE.Bone();
      end.name = `${j.name}_end`;
      end.position.set(j.endSiteOffset.x || 0, j.endSiteOffset.y || 0, j.endSiteOffset.z || 0);
      end.userData.channels = [];
      end.userData.endSite = true;
      b.add(end);
    }
  }
  const all = [];
  bones[0].traverse((o) => all.push(o));
  return { joints: bones, all };
}

const AXES = { X: new THREE.Vector3(1, 0, 0), Y: new THREE.Vector3(0, 1, 0), Z: new THREE.Vector3(0, 0, 1) };
const tmpQ = new THREE.Quaternion();
function applyFrame(joints, values) {
  let k = 0;
  for (const b of joints) {
    b.position.copy(b.userData.offset);
    b.quaternion.set(0, 0, 0, 1);
    for (const c of b.userData.channels) {
      const v = values[k++] || 0;
      if (c.endsWith('_POSITION')) {
        b.position[c[0].toLowerCase()] += v;
      } else {
        tmpQ.setFromAxisAngle(AXES[c[0]], v * Math.PI / 180);
        b.quaternion.multiply(tmpQ);
      }
    }
  }
}

// ---------------------------------------------------------------- timeline

// Syllables, pitch accents (bar height = strength), placed gestures, and the
// 15 viseme tracks as a strip chart, with the playhead.
class Timeline {
  constructor(canvas, caption) {
    this.canvas = canvas;
    this.caption = caption;
    this.data = null;
    this.duration = 0;
    this.onSeek = () => {};
    canvas.addEventListener('pointerdown', (e) => {
      const r = canvas.getBoundingClientRect();
      this.onSeek(((e.clientX - r.left) / r.width) * this.duration);
    });
  }
  set(data, duration) {
    this.changed = true;
    this.data = data;
    this.duration = duration;
    const d = data || {};
    this.caption.textContent = `${(d.syllables || []).length} syllables, ${(d.accents || []).length} pitch accents, ` +
      `${(d.gestures || []).length} gestures, ${d.visemes ? d.visemes.frames.length : 0} viseme frames over ` +
      `${duration.toFixed(2)} s`;
  }
  // The tracks are drawn once into an offscreen canvas (thousands of viseme
  // cells); each frame copies it and draws the playhead.
  draw(t) {
    this.drawnAt = t;
    const c = this.canvas;
    const w = c.clientWidth, h = c.clientHeight;
    if (c.width !== w || c.height !== h) { c.width = w; c.height = h; this.changed = true; }
    if (!this.cache) this.cache = document.createElement('canvas');
    if (this.changed || this.cache.width !== w || this.cache.height !== h) {
      this.cache.width = w;
      this.cache.height = h;
      this.drawTracks(this.cache.getContext('2d'), w, h);
      this.changed = false;
    }
    const g = c.getContext('2d');
    g.clearRect(0, 0, w, h);
    g.drawImage(this.cache, 0, 0);
    const label = 70, x = (s) => label + (s / Math.max(this.duration, 1e-6)) * (w - label - 4);
    g.strokeStyle = '#c22';
    g.lineWidth = 2;
    g.beginPath();
    g.moveTo(x(t), 0);
    g.lineTo(x(t), h);
    g.stroke();
  }

  drawTracks(g, w, h) {
    g.clearRect(0, 0, w, h);
    g.font = '11px system-ui, sans-serif';
    const label = 70, x = (s) => label + (s / Math.max(this.duration, 1e-6)) * (w - label - 4);
    const rows = [['syllables', 0, 16], ['accents', 18, 30], ['gestures', 50, 16]];
    g.fillStyle = '#445';
    for (const [name, y] of rows) g.fillText(name, 4, y + 12);
    const d = this.data || {};
    g.fillStyle = '#9fb8d4';
    for (const s of d.syllables || []) g.fillRect(x(s.startS || 0), 2, Math.max(x(s.endS || 0) - x(s.startS || 0) - 1, 1), 12);
    g.fillStyle = '#d0603a';
    for (const a of d.accents || []) {
      const hh = 4 + 26 * (a.strength || 0);
      g.fillRect(x(a.timeS || 0) - 2, 48 - hh, 4, hh);
    }
    (d.gestures || []).forEach((gs, i) => {
      g.fillStyle = i % 2 === 0 ? '#3a9d6a' : '#7cc79b';  // neighbours in two shades
      g.fillRect(x(gs.startS), 52, Math.max(x(gs.endS) - x(gs.startS) - 1, 3), 12);
    });
    // Visemes: one row each, alpha = weight.
    const top = 70, rh = Math.max((h - top - 2) / 15, 3);
    g.font = `${Math.min(Math.floor(rh), 11)}px system-ui, sans-serif`;
    for (let i = 0; i < 15; ++i) {
      g.fillStyle = '#667';
      g.fillText(VISEMES[i], 4, top + i * rh + rh - 1);
    }
    if (d.visemes) {
      const ft = d.visemes.frameTimeS || 1 / 30;
      const cats = (d.visemes.categories || []).map((cName) => VISEMES.indexOf(cName.replace('VISEME_CATEGORY_', '')));
      for (const f of d.visemes.frames) {
        const x0 = x(f.timeS || 0), x1 = x((f.timeS || 0) + ft);
        (f.weights || []).forEach((wgt, j) => {
          if (wgt <= 0.02) return;
          g.fillStyle = `rgba(80, 60, 160, ${Math.min(wgt, 1)})`;
          g.fillRect(x0, top + (cats[j] >= 0 ? cats[j] : j) * rh, Math.max(x1 - x0, 1), rh - 1);
        });
      }
    }
  }
}

// ---------------------------------------------------------------- the page

const socket = new Socket(`${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}/ws`);
socket.onState = (ok, text) => {
  $('connection').textContent = text;
  $('connection').dataset.ok = ok ? 'yes' : 'no';
};
const views = [new SkeletonView($('view-a')), new SkeletonView($('view-b'))];
renderer.onRendered = () => advance(performance.now());
const timeline = new Timeline($('timeline'), $('timeline-caption'));
const audio = new Audio();
const state = {
  playing: false, time: 0, duration: 0, speed: 1, lastTick: performance.now(), paintedAt: 0, painted: '',
  live: null, framesReceived: 0, lags: [], shownLags: [], audioUrl: null, results: [null, null],
  animated: null,  // the last Animate result {bvh, name, face}: what "Download on the character" writes
};

function setDuration() {
  state.duration = Math.max(views[0].duration, $('view-b').hidden ? 0 : views[1].duration, timeline.duration || 0);
  $('scrub').max = String(state.duration || 1);
}

function play(on) {
  state.playing = on;
  state.lastTick = performance.now();
  $('play').textContent = on ? 'Pause' : 'Play';
  $('play').setAttribute('aria-pressed', on ? 'true' : 'false');
  if (on && state.time >= state.duration) state.time = 0;
  if (on && audio.src) {
    audio.currentTime = state.time;
    audio.playbackRate = state.speed;
    audio.play().catch(() => {});   // no sound without a user gesture; the clock still runs
  } else {
    audio.pause();
  }
}

function seek(t) {
  state.time = Math.min(Math.max(t, 0), state.duration);
  if (audio.src) audio.currentTime = state.time;
}

// The page's clock runs on performance.now(); the audio follows it (re-seeked
// when it drifts by more than 80 ms), so that motion and sound stay together
// even where the audio cannot play. advance() moves the clock, poses the
// views and sends them to the renderer when it is free: at each animation
// frame and as soon as the renderer has drawn one (so the next frame need
// not wait for the next animation frame). Returns whether it posed.
function advance(now) {
  const dt = Math.max(now - state.lastTick, 0) / 1000;
  state.lastTick = now;
  if (state.playing && !state.live) {
    state.time += dt * state.speed;
    if (state.time >= state.duration) {
      state.time = state.duration;
      play(false);
    }
    if (audio.src && !audio.paused && Math.abs(audio.currentTime - state.time) > 0.08) audio.currentTime = state.time;
  }
  // While the renderer draws the last frame, the page does not pose.
  const shown = $('view-b').hidden ? [views[0]] : views;
  if (shown.some((v) => v.busy())) return false;
  if (!state.live) for (const v of shown) v.setTime(state.time);
  for (const v of shown) v.render();
  return true;
}

// Each animation frame: advance, and the clock, scrub bar and timeline's
// playhead when they changed, at most every 100 ms while the renderer is
// busy (their repaints take the CPU that software WebGL's rasteriser needs;
// live, the timeline of an earlier recording is left as it is).
// While live, the page's readouts (the clock, the slider, the live panel's
// counters) change at most every READOUT_MS: each change lays out and
// repaints part of the page, and in software rendering that took the CPU the
// character's frames need (the live frames come at 30 fps, the audio chunks
// at 50 a second).
const READOUT_MS = 250;

function tick(now) {
  const posed = advance(now);
  const shown = `${state.time}/${state.duration}/${Boolean(state.live)}`;
  const due = state.live ? now - state.paintedAt >= READOUT_MS : posed || now - state.paintedAt > 100;
  if (due && shown !== state.painted) {
    state.paintedAt = now;
    state.painted = shown;
    $('scrub').value = String(state.time);
    $('clock').textContent = state.live ? `live ${state.time.toFixed(2)} s`
      : `${state.time.toFixed(2)} / ${state.duration.toFixed(2)} s`;
    if (!state.live && state.time !== timeline.drawnAt) timeline.draw(state.time);
  }
  if (timeline.changed || $('timeline').clientWidth !== $('timeline').width) timeline.draw(state.time);
  requestAnimationFrame(tick);
}

$('play').addEventListener('click', () => play(!state.playing));
$('scrub').addEventListener('input', () => seek(parseFloat($('scrub').value)));
$('speed').addEventListener('change', () => {
  state.speed = parseFloat($('speed').value);
  audio.playbackRate = state.speed;
});
$('side-by-side').addEventListener('change', () => {
  $('view-b').hidden = !$('side-by-side').checked;
  $('views').classList.toggle('two', $('side-by-side').checked);
  setDuration();
});
timeline.onSeek = seek;
$('timeline').addEventListener('keydown', (e) => {
  if (e.key === 'ArrowLeft') { seek(state.time - 0.1); e.preventDefault(); }
  if (e.key === 'ArrowRight') { seek(state.time + 0.1); e.preventDefault(); }
});
document.addEventListener('keydown', (e) => {
  if (e.key === ' ' && !['INPUT', 'SELECT', 'BUTTON', 'TEXTAREA'].includes(document.activeElement.tagName)) {
    play(!state.playing);
    e.preventDefault();
  }
});

// Samples offered by the studio (GET /samples/).
async function loadSamples() {
  const list = (await (await fetch('/samples/')).json()).samples;
  for (const s of list) {
    const option = new Option(s.name, s.url);
    (s.kind === 'wav' ? $('wav-sample') : $('bvh-sample')).add(option);
  }
}

// ---- play a BVH

// ---- the character: bundled (GET /characters/) or the user's GLB / VRM

const characterState = { info: null, error: '' };

function characterStatus(text) { $('character-status').textContent = text; }

// The studio loads the rig (its roles) and the page the GLB; both views
// get the character, and the clips they hold are retargeted onto it.
async function selectCharacter(request, bytes) {
  const info = await socket.call('character', request);
  const buffer = bytes || await (await fetch(info.url)).arrayBuffer();
  await Promise.all(views.map((v) => v.setCharacter(info, buffer)));
  characterState.info = info;
  // A bundled character's credit line, else a VRM's own (its meta).
  $('character-credit').textContent = info.credit || (views[0].characterDrawn || {}).credit || '';
  const roles = (info.mappedRoles || []).length;
  characterStatus(`${info.name}: ${(info.joints || []).length} joints, ${roles} roles` +
    ((info.unmappedRoles || []).length ? ` (no ${(info.unmappedRoles || []).filter((r) => !/\d$/.test(r)).join(', ') || 'fingers'})` : ''));
  refreshCharacterDownload();
  await Promise.all(views.map((v, slot) => (v.bvhText ? retargetInto(slot) : null)));
}

// "Download on the character": the last Animate result with its face,
// written by the studio for the chosen character (export_motion): a VRM
// Animation for a VRM (any VRM app plays it), else the character's GLB with
// the animation (Blender, Unity, Unreal).
function characterExport() {
  const info = characterState.info;
  if (!info || !state.animated) return null;
  const vrm = /^vrm/.test(info.format || '');
  return { info, vrm, label: `${info.name.replace(/\.(glb|vrm)$/i, '').replace(/_/g, ' ')} ` +
                             (vrm ? '(.vrma, for VRM apps)' : '(.glb, for Blender, Unity, Unreal)') };
}

function refreshCharacterDownload() {
  const e = characterExport();
  $('download-character').hidden = !e;
  if (e) $('download-character').textContent = `Download on ${e.label}`;
}

$('download-character').addEventListener('click', async () => {
  const e = characterExport();
  if (!e) return;
  const button = $('download-character');
  button.disabled = true;
  const status = $('animate-status');
  try {
    const last = state.animated;
    const request = { bvh: bytesToBase64(new TextEncoder().encode(last.bvh)), name: last.name,
                      format: e.vrm ? 'EXPORT_FORMAT_VRMA' : 'EXPORT_FORMAT_GLB' };
    if (last.face && (last.face.frames || []).length > 0) request.face = last.face;
    status.textContent = `writing ${last.name} on ${e.info.name}…`;
    const file = await socket.call('exportMotion', request);
    const bin = atob(file.data || '');
    const bytes = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; ++i) bytes[i] = bin.charCodeAt(i);
    const a = document.createElement('a');
    a.href = URL.createObjectURL(new Blob([bytes], { type: file.mediaType }));
    a.download = file.fileName;
    document.body.appendChild(a);
    a.click();
    a.remove();
    setTimeout(() => URL.revokeObjectURL(a.href), 60000);
    status.textContent = `${file.fileName}: ${(bytes.length / 1e6).toFixed(2)} MB on ${e.info.name}`;
  } catch (err) {
    status.textContent = `download on the character: ${err.message}`;
  } finally {
    button.disabled = false;
  }
});

async function loadCharacters() {
  const list = (await (await fetch('/characters/')).json()).characters || [];
  for (const c of list) $('character').add(new Option(c.name.replace(/\.(glb|vrm)$/i, '').replace(/_/g, ' '), c.name));
  if (list.length > 0) {
    // The Quaternius man first (the lightest to draw), else the first.
    const first = (list.find((c) => c.name === 'quaternius_man_casual.glb') || list[0]).name;
    $('character').value = first;
    await socket.ready;
    await selectCharacter({ bundled: first }).catch((err) => characterStatus(`character: ${err.message}`));
  }
}

$('character').addEventListener('change', () => {
  const name = $('character').value;
  if (!name) {
    for (const v of views) v.setCharacter(null).catch((err) => characterStatus(`character: ${err.message}`));
    characterState.info = null;
    refreshCharacterDownload();
    $('character-credit').textContent = '';
    characterStatus('stick figure only');
    return;
  }
  selectCharacter({ bundled: name }).catch((err) => characterStatus(`character: ${err.message}`));
});

$('character-file').addEventListener('change', async () => {
  const file = $('character-file').files[0];
  if (!file) return;
  const limit = Number((socket.hello || {}).maxCharacterBytes || 0);
  if (limit > 0 && file.size > limit) {
    characterStatus(`character.glb: ${file.name} is ${file.size} bytes, the studio takes at most ${limit}`);
    return;
  }
  characterStatus(`loading ${file.name}…`);
  try {
    const bytes = await file.arrayBuffer();
    await selectCharacter({ glb: bytesToBase64(new Uint8Array(bytes)), name: file.name }, bytes);
    $('character').value = '';
  } catch (err) {
    characterStatus(err.message.replace(/^INVALID_ARGUMENT: /, ''));
  }
});

$('close-up').addEventListener('change', () => {
  for (const v of views) v.setCloseUp($('close-up').checked);
});

$('stick').addEventListener('change', () => {
  for (const v of views) {
    v.showStick = $('stick').checked;
    v.applyVisibility();
  }
});

// The view's clip onto the socket's character (the studio retargets).
async function retargetInto(slot) {
  const v = views[slot];
  if (!characterState.info || !v.bvhText) return;
  const text = v.bvhText;
  try {
    // An animated recording's face (AnimateResponse.face) goes with it: the
    // studio maps it onto the character's face targets.
    const request = { bvh: bytesToBase64(new TextEncoder().encode(text)), name: v.caption.textContent };
    if (v.faceTrack && (v.faceTrack.frames || []).length > 0) request.face = v.faceTrack;
    const motion = await socket.call('retarget', request);
    if (v.bvhText === text) v.setCharacterMotion(decodeMotion(motion));
  } catch (err) {
    characterStatus(`retarget: ${err.message}`);
  }
}

async function loadMotion(slot, text, name) {
  views[slot].loadBvh(text, name);
  if (slot === 0 && state.results[0] === null) {
    audio.removeAttribute('src');
    timeline.set(null, views[0].duration);
  }
  setDuration();
  seek(0);
}

$('play-bvh').addEventListener('click', async () => {
  stopLive();
  const file = $('bvh-file').files[0];
  try {
    const text = file ? await file.text() : await (await fetch($('bvh-sample').value)).text();
    const name = file ? file.name : $('bvh-sample').selectedOptions[0].text;
    state.results[0] = null;
    await loadMotion(0, text, name);
    retargetInto(0);
    $('bvh-status').textContent = `${name}: ${views[0].bones.length} joints, ${views[0].duration.toFixed(2)} s`;
    play(true);
  } catch (err) {
    $('bvh-status').textContent = `could not load: ${err.message}`;
  }
});

// ---- animate a recording

$('emphasis').addEventListener('input', () => { $('emphasis-value').textContent = (+$('emphasis').value).toFixed(1); });

function gesturesOf(response) {
  const out = [];
  for (const s of response.segments || []) out.push({ startS: s.startS || 0, endS: s.endS || 0, label: s.clip });
  for (const a of response.accentReport || []) {
    const apex = a.apexS || 0;
    out.push({ startS: Math.max(apex - 0.15, 0), endS: apex + 0.15, label: `phrase ${a.phraseIndex || 0}` });
  }
  return out;
}

$('animate-form').addEventListener('submit', async (e) => {
  e.preventDefault();
  stopLive();
  const slot = parseInt($('slot').value, 10);
  const file = $('wav-file').files[0];
  const status = $('animate-status');
  $('animate').disabled = true;
  try {
    const bytes = new Uint8Array(file ? await file.arrayBuffer() : await (await fetch($('wav-sample').value)).arrayBuffer());
    const name = file ? file.name : $('wav-sample').selectedOptions[0].text;
    const method = $('method').value;
    const audioField = { format: { encoding: 'AUDIO_ENCODING_FILE' }, data: bytesToBase64(bytes), name };
    const request = { audio: audioField, method, visemes: $('visemes').checked, format: 'MOTION_FORMAT_BVH',
                      gestureStyle: { gestureEmphasis: parseFloat($('emphasis').value) } };
    if ($('style').value) request.style = { toneWeights: { [$('style').value]: 1 } };
    status.textContent = `animating ${name} (${method.replace('METHOD_', '').toLowerCase()})…`;
    const started = performance.now();
    const [animated, analyzed] = await Promise.all([
      socket.call('animate', request),
      socket.call('analyze', { audio: audioField, omitFrames: true }).catch(() => null),
    ]);
    const bvh = base64ToText(animated.motion.bvh);
    state.results[slot] = { response: animated, bvh, name };
    if (slot === 1 && !$('side-by-side').checked) $('side-by-side').click();
    views[slot].loadBvh(bvh, `${name} · ${(animated.method || method).replace('METHOD_', '').toLowerCase()}`,
                        animated.face || null);
    retargetInto(slot);
    const track = analyzed ? analyzed.track : {};
    timeline.set({ syllables: track.syllables || [], accents: (animated.prosody || {}).accents || track.accents || [],
                   gestures: gesturesOf(animated), visemes: animated.visemes || null },
                 (animated.prosody || {}).durationS || views[slot].duration);
    if (state.audioUrl) URL.revokeObjectURL(state.audioUrl);
    state.audioUrl = URL.createObjectURL(new Blob([bytes], { type: 'audio/wav' }));
    audio.src = state.audioUrl;
    setDuration();
    // Downloads.
    const dl = $('download-bvh');
    dl.href = URL.createObjectURL(new Blob([bvh], { type: 'text/plain' }));
    dl.download = name.replace(/\.wav$/i, '') + '.bvh';
    dl.hidden = false;
    const dv = $('download-visemes');
    dv.hidden = !animated.visemes;
    if (animated.visemes) dv.href = URL.createObjectURL(new Blob([JSON.stringify(animated.visemes, null, 1)], { type: 'application/json' }));
    state.animated = { bvh, name: name.replace(/\.[a-z0-9]+$/i, '') + '.bvh', face: animated.face || null };
    refreshCharacterDownload();
    const seconds = ((performance.now() - started) / 1000).toFixed(2);
    status.textContent = `${name}: ${views[slot].duration.toFixed(2)} s of motion, ` +
      `${((animated.prosody || {}).accents || []).length} accents, in ${seconds} s`;
    seek(0);
    play(true);
  } catch (err) {
    status.textContent = `animate failed: ${err.message}`;
  } finally {
    $('animate').disabled = false;
  }
});

// ---- live: microphone → AudioWorklet → 20 ms S16LE chunks → StreamAnimate

function percentile(values, p) {
  if (values.length === 0) return 0;
  const sorted = [...values].sort((a, b) => a - b);
  return sorted[Math.min(sorted.length - 1, Math.ceil((p / 100) * sorted.length) - 1)];
}

// `recording` ({url, name}): a recording streamed as if spoken (the cube
// panel's "Stream the recording") instead of the microphone.
async function startLive(recording) {
  const status = $('live-status');
  play(false);
  status.textContent = recording ? `streaming ${recording.name}…` : 'asking for the microphone…';
  const stream = recording ? null : await navigator.mediaDevices.getUserMedia({
    audio: { channelCount: 1, echoCancellation: false, noiseSuppression: false, autoGainControl: false } });
  const context = new AudioContext({ sampleRate: LIVE_RATE_HZ });
  await context.resume();  // a context made after an await may start suspended
  await context.audioWorklet.addModule('/static/capture-worklet.js');
  const source = recording ? await recordingSource(context, recording) : context.createMediaStreamSource(stream);
  const node = new AudioWorkletNode(context, 'kinemo-capture', {
    processorOptions: { chunkSamples: Math.round(LIVE_RATE_HZ * CHUNK_S) } });
  const vmc = vmcTarget();  // read once: the panel may change while the stream runs
  const live = { stream, context, node, source, recording, sent: [], joints: null, frameTimeS: 1 / 30, id: 0, sequence: 0,
                 vmcAddress: vmc.vmc?.address };
  state.live = live;
  state.framesReceived = 0;
  state.lags = [];
  state.shownLags = [];
  live.id = await socket.open('stream', {
    config: { format: { encoding: 'AUDIO_ENCODING_PCM_S16LE', sampleRateHz: LIVE_RATE_HZ, channels: 1 },
              method: 'METHOD_GESTURE_CONTROLLER', ...cubeFollowed(), ...vmc } }, (m) => onLiveMessage(live, m));
  node.port.onmessage = (e) => {
    if (state.live !== live) return;
    const pcm = new Int16Array(e.data);
    const seq = live.sequence++;
    live.sent[seq] = performance.now();
    socket.send({ id: live.id, stream: { chunk: { sequenceNumber: seq, data: bytesToBase64(new Uint8Array(pcm.buffer)) } } });
    showLiveCounters(live);
  };
  source.connect(node);
  if (recording) source.start();
  $('live').textContent = recording ? 'Stop the recording' : 'Stop microphone';
  $('live').setAttribute('aria-pressed', 'true');
  status.textContent = (recording ? `streaming ${recording.name}: watch view A` : 'listening: speak and watch view A') +
    (live.vmcAddress ? `; sending to VMC ${live.vmcAddress}` : '');
}

// The live panel's VMC receiver (StreamAnimateConfig.vmc), when an address
// is given: the coordinator sends the stream's frames there as they go out.
function vmcTarget() {
  const address = $('vmc-address').value.trim();
  if (!address) return {};
  return { vmc: { address, boneNames: $('vmc-bones').value, blendNames: $('vmc-blend').value } };
}

// Motion lag of a frame at audio time t: now − the send time of the chunk
// holding t (a frame within 1/1000 of a frame of a chunk's end belongs to the
// next chunk), as services/coordinator/client/live_client.h defines it.
function onLiveMessage(live, m) {
  if (m.error) {
    if (state.live === live) stopLive();
    $('live-status').textContent = `live stream failed: ${m.error.message}`;  // after stopLive's own text
    return;
  }
  if (m.ended) {
    if (state.live !== live) $('live-status').textContent += ' — stream ended';
    return;
  }
  if (m.characterMotion) {  // the frames just received, on the character (drawn at the next animation frame)
    const motion = decodeMotion(m.characterMotion);
    const c = views[0].character;
    if (c && motion.frames > 0 && motion.character === c.name) {
      c.setFrame(motion, motion.frames - 1);
      views[0].poseChanged = views[0].dirty = true;
      views[0].render();  // to the renderer now, unless it is drawing
      live.characterFrames = (live.characterFrames || 0) + motion.frames;
      state.characterFramesReceived = (state.characterFramesReceived || 0) + motion.frames;
    }
    return;
  }
  const s = m.stream || {};
  if (s.header) {
    const { joints, all } = bonesFromSkeleton(s.header.skeleton);
    live.joints = joints;
    live.frameTimeS = s.header.frameTimeS || 1 / 30;
    views[0].setBones(joints, `live: ${live.recording ? live.recording.name : 'microphone'}`);
    views[0].bones = all;
    live.characterFrames = 0;
  } else if (s.frames && live.joints) {
    const now = performance.now();
    const frames = s.frames.frames || [];
    for (const f of frames) {
      const t = f.timeS || 0;
      const chunk = Math.floor((t + live.frameTimeS / 1000) / CHUNK_S);
      if (live.sent[chunk] !== undefined) {
        state.lags.push(now - live.sent[chunk]);
        views[0].lagRef = performance.timeOrigin + live.sent[chunk];  // for the lag until it is drawn
      }
    }
    state.framesReceived += frames.length;
    if (frames.length > 0) {
      applyFrame(live.joints, frames[frames.length - 1].values || []);
      if (!live.fitted) {
        views[0].fit();  // scale from the first posed frame
        live.fitted = true;
      }
      views[0].updateMeshes();
      if (views[0].stickVisible()) views[0].render();  // the character's pose follows in character_motion
      state.time = frames[frames.length - 1].timeS || 0;
    }
    showLiveCounters(live);
  } else if (s.toneChange) {
    showTone(s.toneChange);
  } else if (s.summary) {
    showLiveCounters(live, true);
    const vmc = live.vmcAddress ? `; to VMC ${live.vmcAddress}: ${s.summary.vmcFrames || 0} frames in ` +
      `${s.summary.vmcPackets || 0} datagrams, ${s.summary.vmcBones || 0} bones, ` +
      `${s.summary.vmcBlendshapes || 0} blend shapes` : '';
    $('live-status').textContent = `stream summary: ${(s.summary.audioS || 0).toFixed(1)} s of audio, ` +
      `${s.summary.frames || 0} frames, ${s.summary.accents || 0} accents${vmc}`;
  }
}

// The live panel's counters (audio sent, frames, lag), at most every
// READOUT_MS (`force`: now).
function showLiveCounters(live, force = false) {
  const now = performance.now();
  if (!force && now - (live.countersAt || 0) < READOUT_MS) return;
  live.countersAt = now;
  $('live-audio').textContent = `${(live.sequence * CHUNK_S).toFixed(1)} s`;
  $('live-frames').textContent = String(state.framesReceived);
  $('live-lag-p50').textContent = `${percentile(state.lags, 50).toFixed(0)} ms`;
  $('live-lag-p99').textContent = `${percentile(state.lags, 99).toFixed(0)} ms`;
}

function stopLive() {
  const live = state.live;
  if (!live) return;
  showLiveCounters(live, true);
  state.live = null;
  live.node.port.onmessage = null;
  live.source.disconnect();
  if (live.stream) live.stream.getTracks().forEach((t) => t.stop());
  if (live.recording) stopRecording(live.source);
  live.context.close();
  if (socket.ws.readyState === WebSocket.OPEN) socket.send({ id: live.id, streamEnd: {} });
  $('live').textContent = 'Start microphone';
  $('live').setAttribute('aria-pressed', 'false');
  $('live-status').textContent = `stopped after ${(live.sequence * CHUNK_S).toFixed(1)} s; ` +
    `motion lag p99 ${percentile(state.lags, 99).toFixed(0)} ms`;
}

$('live').addEventListener('click', () => {
  if (state.live) stopLive();
  else startLive().catch((err) => { stopLive(); $('live-status').textContent = `microphone: ${err.message}`; });
});

// ---- Vleo–Pleo sessions

const EMOTION = (e) => (e || 'EMOTION_UNSPECIFIED').replace('EMOTION_', '').toLowerCase();
const ACTION = (a) => (a || 'ACTION_UNSPECIFIED').replace('ACTION_', '').toLowerCase();
const session = { id: '', watch: 0, emotion: '' };

function showEmotion(emotion, valence) {
  session.emotion = EMOTION(emotion);
  $('pleo-emotion').textContent = session.emotion;
  $('pleo').dataset.emotion = session.emotion;
  if (valence !== undefined) $('valence').value = valence;
  const option = [...$('session').options].find((o) => o.value === session.id);
  if (option) option.textContent = option.textContent.replace(/, \w+\)$/, `, ${session.emotion})`);
}

function logEvent(text) {
  const li = document.createElement('li');
  li.textContent = text;
  $('events').prepend(li);
  while ($('events').children.length > 12) $('events').lastChild.remove();
}

function onSessionEvent(m) {
  if (m.error) { logEvent(`watch failed: ${m.error.message}`); return; }
  if (m.ended || !m.sessionEvent) return;
  const e = m.sessionEvent;
  const t = (e.sessionTimeS || 0).toFixed(1);
  if (e.snapshot) {
    const s = e.snapshot;
    showEmotion(s.emotion, s.valence || 0);
    $('vleo-action').textContent = `${ACTION(s.action)} ${(s.intensity || 0).toFixed(1)}`;
    $('robot-status').textContent = s.robotConnected ? 'connected' : 'not connected';
    $('robot-emotion').textContent = EMOTION(s.robotEmotion);
    $('cube-status').textContent = s.cubeAttached ? (s.cubeVisible ? 'attached, visible' : 'attached') : 'not attached';
    showCube(s.cubeAttached ? s.cubeFace : undefined, s.cubeAttached ? s.cubeIntensity : 0);  // '–' without a cube
  } else if (e.emotionChanged) {
    const c = e.emotionChanged;
    showEmotion(c.toEmotion, c.valence || 0);
    logEvent(`${t} s: ${EMOTION(c.fromEmotion)} → ${EMOTION(c.toEmotion)} (${ACTION(c.action)})`);
  } else if (e.actionChanged) {
    const a = e.actionChanged;
    $('vleo-action').textContent = `${ACTION(a.action)} ${(a.intensity || 0).toFixed(1)}${a.fromCube ? ' (cube)' : ''}`;
    if (a.fromCube) $('cube-intensity').textContent = (a.intensity || 0).toFixed(2);
    logEvent(`${t} s: Vleo ${ACTION(a.action)} at ${(a.intensity || 0).toFixed(1)}`);
  } else if (e.robotCommanded) {
    const r = e.robotCommanded;
    $('robot-emotion').textContent = r.error ? `error: ${r.error}` : EMOTION(r.emotion);
    logEvent(`${t} s: robot told ${EMOTION(r.emotion)}${r.latencyMs ? ` in ${r.latencyMs.toFixed(0)} ms` : ''}`);
  } else if (e.robotStatusChanged) {
    const r = e.robotStatusChanged;
    $('robot-status').textContent = r.connected ? 'connected' : 'not connected';
    $('robot-emotion').textContent = EMOTION(r.shownEmotion);
    if (r.batteryPercent !== undefined) $('robot-battery').textContent = `${r.batteryPercent.toFixed(0)} %`;
  } else if (e.cubeStatusChanged) {
    const c = e.cubeStatusChanged;
    $('cube-status').textContent = c.attached ? (c.visible ? 'attached, visible' : 'attached, not visible')
      : `not attached${c.reason ? ` (${c.reason})` : ''}`;
    // Each event carries the cube's face and intensity after it; the attach's
    // carries the first tracked frame's (before any turn).
    // A detached cube shows no face ('–'), not the last one it had.
    showCube(c.attached ? c.topFace : undefined, c.attached ? c.intensity : 0);
    const ev = c.cubeEvent || {};
    if (ev.intensityChanged) $('cube-intensity').textContent = (ev.intensityChanged.toIntensity || 0).toFixed(2);
    if (ev.actionLaunched) $('cube-intensity').textContent = (ev.actionLaunched.intensity || 0).toFixed(2);
  } else if (e.sessionClosed) {
    logEvent(`${t} s: session closed (${e.sessionClosed.reason || ''})`);
  }
}

// The cube's top face (CUBE_FACE_…; '–' until the tracker saw it) and
// rotation intensity, as a session or its cube events report them.
function showCube(face, intensity) {
  const name = (face || 'CUBE_FACE_UNSPECIFIED').replace('CUBE_FACE_', '').toLowerCase();
  $('cube-face').textContent = name === 'unspecified' ? '–' : name;
  $('cube-intensity').textContent = (intensity || 0).toFixed(2);
}

async function watch(id) {
  if (session.watch) socket.send({ id: session.watch, cancel: {} });
  if (id !== session.id && cube.attachedSession) {  // another session: its cube's AR view goes
    cube.attachedSession = '';
    hideCubeAr();
  }
  session.id = id;
  session.watch = id ? await socket.open('watchSession', { sessionId: id }, onSessionEvent) : 0;
}

async function refreshSessions(select) {
  const list = await socket.call('listSessions', {});
  const box = $('session');
  box.textContent = '';
  for (const s of list.sessions || []) box.add(new Option(`${s.sessionId} (${s.robotId}, ${EMOTION(s.emotion)})`, s.sessionId));
  if (select) box.value = select;
  if (box.value && box.value !== session.id) await watch(box.value);
}

$('session-form').addEventListener('submit', async (e) => {
  e.preventDefault();
  try {
    const opened = await socket.call('openSession', { robotId: $('robot-id').value, vleo: 'VLEO_KIND_CLIENT',
                                                      vleoName: 'studio', initialEmotion: $('initial-emotion').value });
    await refreshSessions(opened.session.sessionId);
    logEvent(`opened ${opened.session.sessionId}`);
  } catch (err) {
    logEvent(`open failed: ${err.message}`);
  }
});
$('session').addEventListener('change', () => watch($('session').value));
$('intensity').addEventListener('input', () => { $('intensity-value').textContent = (+$('intensity').value).toFixed(1); });
for (const button of document.querySelectorAll('button.act')) {
  button.addEventListener('click', async () => {
    if (!session.id) { logEvent('open a session first'); return; }
    try {
      await socket.call('act', { sessionId: session.id, action: button.dataset.action,
                                 intensity: parseFloat($('intensity').value) });
    } catch (err) {
      logEvent(`act failed: ${err.message}`);
    }
  });
}

// ---- the cube: a video attached to the session drives Pleo and, through
// the live stream that follows the session, the character's tone

// What the page showed, in order (for the eye and for tests): each distinct
// top face and tone as it came.
const cube = { faces: [], tones: [], tone: '', weight: 0, ar: null, attachedSession: '' };

function cubeStatus(text) { $('cube-attach-status').textContent = text; }

// The AR view (the studio's CubeArVideo): the attached video with the
// character drawn on the table beside the cube, drawn by the studio after the
// attach (at once when drawn before). It shows from when it is ready until
// Detach, the next attach or another session; a video that ended by itself
// (the studio often finishes drawing after that) keeps looping, captioned.
// The live frames never wait for it: the browser decodes it on its own.
function hideCubeAr(caption = '') {
  const video = $('cube-ar-video');
  cube.ar = null;
  video.pause();
  video.removeAttribute('src');
  video.load();
  video.hidden = true;
  $('cube-ar-caption').textContent = caption;
  $('cube-ar').hidden = !caption;
}

function showCubeAr(ar) {
  if (ar.sessionId !== session.id || ar.sessionId !== cube.attachedSession) return;  // an older attach's
  if (ar.error || !ar.url) {
    hideCubeAr(`AR view: ${ar.error || 'none'}`);
    return;
  }
  cube.ar = ar;
  const video = $('cube-ar-video');
  video.src = ar.url;
  video.hidden = false;
  $('cube-ar').hidden = false;
  video.play().catch(() => { /* muted: allowed; a hidden tab may refuse */ });
  cubeArCaption();
}

function cubeArCaption() {
  if (!cube.ar) return;
  const ar = cube.ar;
  const ended = !$('cube-status').textContent.startsWith('attached') ? ' (the video has ended: looping)' : '';
  $('cube-ar-caption').textContent = `AR view${ended}: ${ar.frames || 0} frames, ${ar.width}×${ar.height}` +
    (ar.renderS ? `, drawn in ${ar.renderS.toFixed(1)} s` : '');
}
socket.onCubeAr = showCubeAr;

// The live stream follows the session while a cube is attached to it.
function cubeFollowed() {
  return session.id && $('cube-status').textContent.startsWith('attached') ? { sessionId: session.id } : {};
}

// A stream's tone_change: the tone the character moves in from now.
function showTone(change) {
  if (change.superseded) return;
  cube.tone = change.tone || 'neutral';
  cube.weight = change.weight || 0;
  $('cube-tone').textContent = `${cube.tone} ${cube.weight.toFixed(2)}`;
  if (cube.tones[cube.tones.length - 1] !== cube.tone) cube.tones.push(cube.tone);
  logEvent(`${(change.tS || 0).toFixed(1)} s of speech: tone ${cube.tone} ${cube.weight.toFixed(2)} ` +
           `(${ACTION(change.action)})`);
}

// The session's fields (onSessionEvent fills them): faces as they change,
// and Detach while a cube is attached.
new MutationObserver(() => {
  const face = $('cube-face').textContent;
  if (face !== '–' && cube.faces[cube.faces.length - 1] !== face) cube.faces.push(face);
}).observe($('cube-face'), { childList: true, characterData: true, subtree: true });
new MutationObserver(() => {
  $('cube-detach').disabled = !$('cube-status').textContent.startsWith('attached');
  cubeArCaption();
}).observe($('cube-status'), { childList: true, characterData: true, subtree: true });

// A recording as the live source: decoded at the stream's rate and heard;
// the stream ends with it.
async function recordingSource(context, recording) {
  const bytes = await (await fetch(recording.url)).arrayBuffer();
  const source = context.createBufferSource();
  source.buffer = await context.decodeAudioData(bytes);
  source.connect(context.destination);
  source.onended = () => { if (state.live && state.live.source === source) stopLive(); };
  $('cube-play').textContent = 'Stop the recording';
  return source;
}

function stopRecording(source) {
  source.onended = null;
  try { source.stop(); } catch (e) { /* never started */ }
  $('cube-play').textContent = 'Stream the recording';
}

async function ensureSession() {
  if (session.id) return session.id;
  const opened = await socket.call('openSession', {
    robotId: $('robot-id').value, vleo: 'VLEO_KIND_CUBE', vleoName: 'studio cube',
    initialEmotion: $('initial-emotion').value });
  await refreshSessions(opened.session.sessionId);
  logEvent(`opened ${opened.session.sessionId}`);
  return opened.session.sessionId;
}

async function attachCube() {
  const file = $('cube-file').files[0];
  const request = {};
  let name = $('cube-scenario').value;
  if (file) {
    const limit = Number((socket.hello || {}).maxCubeVideoBytes || 0);
    if (limit > 0 && file.size > limit) {
      throw new Error(`attach_cube.upload: ${file.name} is ${file.size} bytes, the studio takes at most ${limit}`);
    }
    name = file.name;
    request.upload = bytesToBase64(new Uint8Array(await file.arrayBuffer()));
    request.name = file.name;
    const camera = $('cube-camera').files[0];
    if (camera) request.cameraYaml = await camera.text();
  } else {
    if (!name) throw new Error('attach_cube.bundled: the studio offers no cube video; upload one');
    request.bundled = name;
  }
  cubeStatus(`attaching ${name}${file ? '' : ' (drawn on its first use)'}…`);
  request.sessionId = await ensureSession();
  hideCubeAr();
  cube.attachedSession = '';
  const attached = await socket.call('attachCube', request);
  cube.attachedSession = request.sessionId;
  hideCubeAr('AR view: being drawn…');
  const s = (attached || {}).session || {};
  cube.faces = [];
  cube.tones = [];
  $('cube-status').textContent = s.cubeVisible ? 'attached, visible' : 'attached';
  showCube(s.cubeFace, s.cubeIntensity);  // the first tracked frame's, before any turn
  cubeStatus(`${name} attached to ${request.sessionId}: stream speech and watch the tone, the face and Pleo`);
  // A stream already running starts again, in the session.
  if (state.live) {
    const recording = state.live.recording;
    stopLive();
    await startLive(recording);
  }
}

$('cube-attach').addEventListener('click', () => {
  $('cube-attach').disabled = true;
  attachCube()
    .catch((err) => cubeStatus(err.message.replace(/^[A-Z_]+: /, '')))
    .finally(() => { $('cube-attach').disabled = false; });
});
$('cube-detach').addEventListener('click', async () => {
  try {
    await socket.call('detachCube', { sessionId: session.id });
    cube.attachedSession = '';
    hideCubeAr();
    $('cube-status').textContent = 'not attached';
    showCube(undefined, 0);
    cubeStatus('detached: the last action stays current');
  } catch (err) {
    cubeStatus(`detach: ${err.message}`);
  }
});
$('cube-play').addEventListener('click', () => {
  if (state.live) { stopLive(); return; }
  const option = $('wav-sample').selectedOptions[0];
  if (!option) { cubeStatus('choose a recording under Animate speech'); return; }
  startLive({ url: option.value, name: option.textContent })
    .catch((err) => { stopLive(); $('live-status').textContent = `recording: ${err.message}`; });
});

// The scenarios the studio offers (its hello).
async function loadCubeScenarios() {
  await socket.ready;
  const hello = socket.hello || {};
  const box = $('cube-scenario');
  box.textContent = '';
  for (const name of hello.cubeScenarios || []) box.add(new Option(name.replace(/_/g, ' '), name));
  if (box.querySelector('option[value="tone_scenario"]')) box.value = 'tone_scenario';
  if (!Number(hello.maxCubeVideoBytes || 0)) {
    $('cube-attach').disabled = true;
    cubeStatus('attaching a cube is off: the studio has no cube_dir');
  }
}

// ---------------------------------------------------------------- start

window.kinemoStudio = {
  // For tests: what the page shows now.
  stats() {
    return {
      frames_received: state.framesReceived,
      motion_lag_ms_p99: percentile(state.lags, 99),
      playing: state.playing || state.live !== null,
      hand_positions: views[0].handPositions(),
      character: views[0].character ? views[0].character.name : '',
      skinned: views[0].skinned(),
      render_fps: views[0].renderFps(),
      character_hands: views[0].characterHands(),   // as the renderer drew them
      drawn_pose_time_s: views[0].drawnState ? views[0].drawnState.time : -1,
      face: views[0].characterFace(),   // {weights: {target: w}, bound} as drawn
      face_distance_m: views[0].faceDistance(),  // camera to the drawn face
      face_size_m: views[0].drawnState && views[0].drawnState.head ? views[0].drawnState.head.size : null,
      character_frames: views[0].characterMotion ? views[0].characterMotion.frames : 0,
      character_frames_received: state.characterFramesReceived || 0,
      pose_time_s: views[0].time,      // the time view A's figures are posed at
      time_s: state.time,
      duration_s: state.duration,
      pleo_emotion: session.emotion,
      session_id: session.id,
      connected: Boolean(socket.hello) && socket.ws.readyState === WebSocket.OPEN,
      views: views.map((v) => ({ clip: v.mixer ? v.caption.textContent : '', duration_s: v.duration })),
    };
  },
  lags: () => [...state.lags],
  // Live: chunk sent -> the renderer's first frame showing a frame of it (ms).
  shownLags: () => [...state.shownLags],

  stopLive,

  // For tests and benchmarks: the page's frame rate over `seconds`, from
  // requestAnimationFrame timing on this thread (`raf_fps`: the page's own
  // frames) and from the renderer's answers for view A (`drawn_fps`: frames
  // drawn; the views are drawn in a worker): frames per second, and the
  // intervals' p50 / p95 in ms. Resolves when done.
  measureFps(seconds) {
    return new Promise((resolve) => {
      const raf = [], drawn = [];
      const start = performance.now(), end = start + seconds * 1000;
      const before = views[0].onDrawn;
      views[0].onDrawn = (at) => { if (at >= start && at <= end) drawn.push(at); };
      const summary = (times) => {
        const gaps = times.slice(1).map((t, i) => t - times[i]).sort((a, b) => a - b);
        const q = (p) => (gaps.length ? gaps[Math.min(gaps.length - 1, Math.floor(p * gaps.length))] : 0);
        return { frames: times.length, fps: times.length > 1 ? (times.length - 1) * 1000 / (times[times.length - 1] - times[0]) : 0,
                 interval_ms_p50: q(0.5), interval_ms_p95: q(0.95), interval_ms_max: gaps.length ? gaps[gaps.length - 1] : 0 };
      };
      const frame = (t) => {
        if (t <= end) {
          raf.push(t);
          requestAnimationFrame(frame);
          return;
        }
        views[0].onDrawn = before;
        resolve({ seconds, raf: summary(raf), drawn: summary(drawn) });
      };
      requestAnimationFrame(frame);
    });
  },
};
// For tests: what the cube panel shows.
window.kinemoStudio.cube = () => ({
  attached: $('cube-status').textContent.startsWith('attached'), face: $('cube-face').textContent,
  intensity: $('cube-intensity').textContent, tone: cube.tone, weight: cube.weight,
  faces_shown: [...cube.faces], tones_shown: [...cube.tones], status: $('cube-attach-status').textContent,
  pleo_emotion: session.emotion, robot_emotion: $('robot-emotion').textContent, session_id: session.id,
  live_caption: views[0].caption.textContent, live_status: $('live-status').textContent,
  ar: (() => {
    const v = $('cube-ar-video');
    return { url: cube.ar ? cube.ar.url : '', shown: !$('cube-ar').hidden && !v.hidden, caption: $('cube-ar-caption').textContent,
             ready_state: v.readyState, video_width: v.videoWidth, video_height: v.videoHeight,
             current_time_s: v.currentTime, paused: v.paused, error: v.error ? v.error.code : 0 };
  })(),
});

loadCharacters().catch((err) => characterStatus(`characters: ${err.message}`));
loadSamples().then(() => socket.ready).then(() => refreshSessions()).catch((err) => console.warn(err.message));
loadCubeScenarios().catch((err) => cubeStatus(`cube: ${err.message}`));
requestAnimationFrame(tick);
