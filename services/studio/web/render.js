// kinemo studio: drawing the 3D views (three.js, Debian's libjs-three).
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
//                                    {type: 'character', id, drawables} or {.., error}
//   frame {camera: [x y z qx qy qz qw fov], stick, joints, segments,
//          character, pose?: {rotations, translations}, mouth: [open, width], lagRef}
// Answers `rendered` {view, at, lagRef} after each drawn frame: `at` in
// epoch milliseconds (performance.timeOrigin + now) once the frame has been
// handed to the compositor, `lagRef` as the newest frame message carried.
import * as THREE from '/three/build/three.module.js';
import { CharacterModel, CharacterRig, parseGlb } from '/static/character.js';

const BONE_MATERIAL = new THREE.MeshStandardMaterial({ color: 0x4f8fd6, roughness: 0.45, metalness: 0.1 });
const JOINT_MATERIAL = new THREE.MeshStandardMaterial({ color: 0xe8eef5, roughness: 0.6 });
const HAND_MATERIAL = new THREE.MeshStandardMaterial({ color: 0xf2a541, roughness: 0.5 });
const STICK_RADIUS = 0.028;

// One view's scene: floor grid, lights, the stick figure as shaded
// capsules (a cylinder per bone, spheres at the joints), the character.
class ViewScene {
  constructor(canvas, software) {
    // Multisampling only on a GPU: in software (SwiftShader, llvmpipe) it
    // halves the frame rate of the skinned character (14 -> 28 fps measured
    // in headless Chromium on this project's 2-core build machine).
    this.renderer = new THREE.WebGLRenderer({ canvas, antialias: !software });
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0xf4f6f9);
    this.camera = new THREE.PerspectiveCamera(40, 1, 0.05, 100);
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x8899aa, 0.75));
    const sun = new THREE.DirectionalLight(0xffffff, 0.7);
    sun.position.set(2, 4, 3);
    this.scene.add(sun);
    this.scene.add(new THREE.GridHelper(6, 24, 0x9aa7b5, 0xcdd5de));
    this.jointGeometry = new THREE.SphereGeometry(STICK_RADIUS * 1.25, 16, 12);
    this.boneGeometry = new THREE.CylinderGeometry(STICK_RADIUS, STICK_RADIUS, 1, 14, 1);
    this.boneGeometry.translate(0, 0.5, 0);
    this.joints = [];
    this.segments = [];
    this.character = null;
    this.showCharacter = true;
    this.lagRef = 0;
    this.dirty = false;    // draw only when something changed
  }

  size({ width, height, pixelRatio }) {
    this.renderer.setPixelRatio(pixelRatio);
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

  // Returns the number of skinned draw calls.
  setCharacter({ glb, name, info }, onTexture) {
    if (this.character) {
      this.scene.remove(this.character.group);
      this.character.dispose();
      this.character = null;
    }
    this.dirty = true;
    if (!glb) return 0;
    const rig = new CharacterRig(parseGlb(glb, name), info, this.renderer.capabilities.maxVertexUniforms);
    this.character = new CharacterModel(rig);
    this.character.onTexture = onTexture;
    this.character.group.visible = this.showCharacter;
    this.scene.add(this.character.group);
    return this.character.drawables.length;
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
    const model = this.character;
    if (model) {
      model.group.visible = f.character;
      if (f.pose) {
        model.rig.setPose(f.pose.rotations, f.pose.translations);
        model.sync();
      }
      model.setMouth(f.mouth[0], f.mouth[1]);
    }
    if (f.lagRef) this.lagRef = f.lagRef;
    this.dirty = true;
  }

  // Draws when something changed; true if it did.
  render() {
    if (!this.dirty && !(this.character && this.character.dirty)) return false;
    this.dirty = false;
    if (this.character) this.character.dirty = false;
    this.renderer.render(this.scene, this.camera);
    return true;
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
      drawn.push({ type: 'rendered', view, lagRef: v.lagRef });
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
        const drawables = v.setCharacter(m, () => schedule());
        reply({ type: 'character', view: m.view, id: m.id, drawables });
      }
    } catch (err) {
      reply({ type: m.type, view: m.view, id: m.id, error: err.message });
    } finally {
      schedule();
    }
  };
}
