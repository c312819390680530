// kinemo studio: drawing the 3D views (three.js from npm, bundled in
// /libs/kinemo-libs.js).
//
// The page's main thread holds the views' state (bones, BVH clips, the
// character's pose, the orbit camera) and sends each view's latest state
// once per animation frame; this host draws it. The page runs the host in a
// worker (render-worker.js) on OffscreenCanvases: where WebGL runs in
// software (headless Chromium's SwiftShader), each frame ends with a
// readback that blocks the drawing thread until the frame is rasterised
// (~25 ms at a load of 8 on 2 cores), and on the page's main thread that
// held up socket messages (live frames) and the clock. Where a browser has
// no OffscreenCanvas, the page runs the same host itself.
//
// Messages (each with `view`, the view's index):
//   init {canvas, software}          the view's canvas (transferred)
//   size {width, height, pixelRatio} CSS pixels of the canvas
//   stick {hands: Uint8Array, segments}  the stick figure's joints (1 = a
//                                    hand) and bone segments
//   character {id, glb: ArrayBuffer|null, name, info}  answered with
//                                    {type: 'character', id, drawables, height, credit} or {.., error}
//   frame {camera: [x y z qx qy qz qw fov], stick, joints, segments,
//          character, pose?: {rotations, translations}, face?: Float32Array,
//          time, lagRef}
// Answers `rendered` {view, at, lagRef, time, hands, face, head} after each drawn
// frame: `at` in epoch milliseconds (performance.timeOrigin + now) once the
// frame has been handed to the compositor, `lagRef` as the newest frame
// message carried, `time` the page time of the pose drawn, `hands` the
// character's hand joints, `face` its face targets' weights and `head` where
// its face is (head joint at eye level) as drawn.
import * as THREE from '/libs/kinemo-libs.js';
import { CharacterModel } from '/static/character.js';

const BONE_MATERIAL = new THREE.MeshStandardMaterial({ color: 0x4f8fd6, roughness: 0.45, metalness: 0.1 });
const JOINT_MATERIAL = new THREE.MeshStandardMaterial({ color: 0xe8eef5, roughness: 0.6 });
const HAND_MATERIAL = new THREE.MeshStandardMaterial({ color: 0xf2a541, roughness: 0.5 });
const STICK_RADIUS = 0.028;
const SOFTWARE_PIXEL_SCALE = 0.75;

// One view's scene: floor grid, lights, the stick figure as shaded
// capsules (a cylinder per bone, spheres at the joints), the character.
class ViewScene {
  constructor(canvas, software) {
    // Multisampling only on a GPU: in software (SwiftShader, llvmpipe) it
    // halves the frame rate of the skinned character (14 -> 28 fps measured
    // in headless Chromium on this project's 2-core build machine).
    this.renderer = new THREE.WebGLRenderer({ canvas, antialias: !software });
    this.software = software;
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0xf4f6f9);
    this.camera = new THREE.PerspectiveCamera(40, 1, 0.05, 100);
    this.scene.add(this.camera);  // a VRM's eyes look at it
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x8899aa, 2.2));
    const sun = new THREE.DirectionalLight(0xffffff, 2.0);
    sun.position.set(2, 4, 3);
    this.scene.add(sun);
    this.scene.add(new THREE.GridHelper(6, 24, 0x9aa7b5, 0xcdd5de));
    this.jointGeometry = new THREE.SphereGeometry(STICK_RADIUS * 1.25, 16, 12);
    this.boneGeometry = new THREE.CylinderGeometry(STICK_RADIUS, STICK_RADIUS, 1, 14, 1);
    this.boneGeometry.translate(0, 0.5, 0);
    this.joints = [];
    this.segments = [];
    this.character = null;
    this.loading = 0;      // the id of the character being loaded
    this.showCharacter = true;
    this.pose = null;      // the newest pose and face, kept while a character loads
    this.face = null;
    this.time = 0;
    this.drawnAt = 0;
    this.lagRef = 0;
    this.dirty = false;    // draw only when something changed
  }

  // In software WebGL every pixel's shading is CPU time: the canvas is drawn
  // at SOFTWARE_PIXEL_SCALE of the display's pixels and the browser scales it
  // up (a softer picture, nothing changes on a GPU). The VALID man talking
  // live in headless Chromium went 18.9 -> 24.3 fps (Godette 29.5 -> 30.5)
  // on the 2-core build machine at a load of 4 (studio_browser_face).
  size({ width, height, pixelRatio }) {
    this.renderer.setPixelRatio(this.software ? pixelRatio * SOFTWARE_PIXEL_SCALE : pixelRatio);
    this.renderer.setSize(width, height, false);
    this.camera.aspect = width / Math.max(height, 1);
    this.camera.updateProjectionMatrix();
    this.dirty = true;
  }

  stick({ hands, segments }) {
    for (const mesh of [...this.joints, ...this.segments]) this.scene.remove(mesh);
    this.joints = Array.from(hands, (hand) => new THREE.Mesh(this.jointGeometry, hand ? HAND_MATERIAL : JOINT_MATERIAL));
    this.segments = Array.from({ length: segments }, () => new THREE.Mesh(this.boneGeometry, BONE_MATERIAL));
    for (const mesh of [...this.joints, ...this.segments]) {
      mesh.visible = false;
      this.scene.add(mesh);
    }
    this.dirty = true;
  }

  // Loads a character (null: none); resolves with its meshes' count and
  // height. A load overtaken by a later one resolves with null.
  async setCharacter({ id, glb, name, info }) {
    this.loading = id;
    if (this.character) {
      this.scene.remove(this.character.group);
      this.character.dispose();
      this.character = null;
    }
    this.pose = this.face = null;
    this.dirty = true;
    if (!glb) return { drawables: 0, height: 0 };
    const model = await CharacterModel.load(glb, name, info, this.software);
    if (this.loading !== id) {
      model.dispose();
      return null;
    }
    this.character = model;
    model.group.visible = this.showCharacter;
    if (this.pose) model.setPose(this.pose.rotations, this.pose.translations);
    if (this.face) model.setFace(this.face);
    this.scene.add(model.group);
    // Compile the shaders now (the first draw would otherwise stall).
    this.renderer.compile(this.scene, this.camera);
    this.dirty = true;
    return { drawables: model.drawables(), height: model.height, credit: model.credit() };
  }

  frame(f) {
    const c = f.camera;
    this.camera.position.set(c[0], c[1], c[2]);
    this.camera.quaternion.set(c[3], c[4], c[5], c[6]);
    if (this.camera.fov !== c[7]) {
      this.camera.fov = c[7];
      this.camera.updateProjectionMatrix();
    }
    this.joints.forEach((mesh, i) => {
      mesh.visible = f.stick;
      mesh.position.fromArray(f.joints, 3 * i);
    });
    this.segments.forEach((mesh, i) => {
      const o = 8 * i;
      mesh.visible = f.stick;
      mesh.position.fromArray(f.segments, o);
      mesh.quaternion.fromArray(f.segments, o + 3);
      mesh.scale.set(1, f.segments[o + 7], 1);
    });
    this.showCharacter = f.character;
    if (f.pose) this.pose = f.pose;
    if (f.face) this.face = f.face;
    const model = this.character;
    if (model) {
      model.group.visible = f.character;
      if (f.pose) model.setPose(f.pose.rotations, f.pose.translations);
      if (f.face) model.setFace(f.face);
    }
    this.time = f.time;
    if (f.lagRef) this.lagRef = f.lagRef;
    this.dirty = true;
  }

  // Draws when something changed; true if it did.
  render() {
    if (!this.dirty && !(this.character && this.character.dirty)) return false;
    this.dirty = false;
    const now = performance.now();
    if (this.character) {
      this.character.dirty = false;
      this.character.update(this.drawnAt ? (now - this.drawnAt) / 1000 : 0, this.camera);
    }
    this.drawnAt = now;
    this.renderer.render(this.scene, this.camera);
    return true;
  }

  // What the answer to a drawn frame tells the page.
  drawn() {
    const c = this.character;
    return { time: this.time, hands: c ? c.handPositions() : [], face: c ? c.faceState() : null,
             head: c ? c.facePosition() : null };
  }
}

// The host: `reply(message)` answers the page, `requestFrame(callback)`
// schedules a draw (requestAnimationFrame). Returns the message handler.
export function createRenderHost(reply, requestFrame) {
  const views = [];
  let scheduled = false;
  const draw = () => {
    scheduled = false;
    const drawn = [];
    views.forEach((v, view) => {
      if (!v || !v.render()) return;
      drawn.push({ type: 'rendered', view, lagRef: v.lagRef, ...v.drawn() });
      v.lagRef = 0;
    });
    // Answered in the next task: after this one has handed the frames to
    // the compositor (the readback of software WebGL happens there).
    if (drawn.length > 0) {
      setTimeout(() => {
        const at = performance.timeOrigin + performance.now();
        for (const m of drawn) reply({ ...m, at });
      }, 0);
    }
  };
  const schedule = () => {
    if (!scheduled) {
      scheduled = true;
      requestFrame(draw);
    }
  };
  return (m) => {
    try {
      if (m.type === 'init') {
        views[m.view] = new ViewScene(m.canvas, m.software);
        return;
      }
      const v = views[m.view];
      if (!v) throw new Error(`view ${m.view} has no canvas`);
      if (m.type === 'size') v.size(m);
      else if (m.type === 'stick') v.stick(m);
      else if (m.type === 'frame') v.frame(m);
      else if (m.type === 'character') {
        v.setCharacter(m).then((built) => {
          if (built) reply({ type: 'character', view: m.view, id: m.id, ...built });
          else reply({ type: 'character', view: m.view, id: m.id, error: 'replaced by a later character' });
          schedule();
        }, (err) => {
          reply({ type: 'character', view: m.view, id: m.id, error: err.message });
          schedule();
        });
      }
    } catch (err) {
      reply({ type: m.type, view: m.view, id: m.id, error: err.message });
    } finally {
      schedule();
    }
  };
}
