// Checks a VMC recording (receiver.mjs) against the BVH kinemo wrote for the
// same `kinemo animate --stream --vmc` run, with code of its own (the
// humanoid's forward kinematics, a BVH reader, the bone names):
//   - every frame (closed by /VMC/Ext/T) has /VMC/Ext/Root/Pos, /VMC/Ext/OK
//     and a /VMC/Ext/Bone/Pos for every humanoid bone the source drives;
//   - the wrist path: forward kinematics on the received humanoid (root ->
//     hips -> ... -> hand, local positions and rotations, Unity axes) against
//     the BVH's wrists turned into the receiver's frame (docs/vmc.md: the
//     source turned about the vertical so that its rest right -> left hip
//     line is the character's left, Unity's -X; metres), frame by frame
//     (frames matched by /VMC/Ext/T = the BVH frame's time);
//   - bone messages per second per bone, on the receiver's clock;
//   - the face: 13 /VMC/Ext/Blend/Val then /VMC/Ext/Blend/Apply in every
//     frame (--face required), none (--face absent), or either, all frames
//     alike (--face auto); with --visemes (the faces kinemo received, the
//     file of `kinemo animate --visemes`), each frame's blend shapes are the
//     documented mapping of its face (docs/vmc.md: vowel visemes one to one,
//     blinks shared and per eye, the expression's weight), within the file's
//     rounding.
// Prints one JSON line of measures; exits 1 naming what failed.
//
//   node check.mjs --recording R.json --bvh OUT.bvh --kinemo KINEMO.json
//        [--bones unity|vrm1] [--face required|absent|auto] [--visemes V.json] [--max-wrist-error-m 0.01]
import { readFileSync } from "node:fs";

const opt = { bones: "unity", face: "auto", "max-wrist-error-m": "0.01" };
const argv = process.argv.slice(2);
for (let i = 0; i < argv.length; i += 2) opt[argv[i].replace(/^--/, "")] = argv[i + 1];
for (const k of ["recording", "bvh", "kinemo"]) {
  if (!opt[k]) {
    console.error(`check.mjs: --${k} is required`);
    process.exit(2);
  }
}
const failures = [];
const fail = (msg) => failures.push(msg);

// ---- quaternions (x, y, z, w) and vectors ------------------------------------
const qmul = (a, b) => [
  a[3] * b[0] + a[0] * b[3] + a[1] * b[2] - a[2] * b[1],
  a[3] * b[1] - a[0] * b[2] + a[1] * b[3] + a[2] * b[0],
  a[3] * b[2] + a[0] * b[1] - a[1] * b[0] + a[2] * b[3],
  a[3] * b[3] - a[0] * b[0] - a[1] * b[1] - a[2] * b[2],
];
const qrot = (q, v) => {
  const p = qmul(qmul(q, [v[0], v[1], v[2], 0]), [-q[0], -q[1], -q[2], q[3]]);
  return [p[0], p[1], p[2]];
};
const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const norm = (a) => Math.hypot(a[0], a[1], a[2]);

// ---- the humanoid: Unity's HumanBodyBones hierarchy ---------------------------
const unityParent = {
  Hips: null, Spine: "Hips", Chest: "Spine", UpperChest: "Chest", Neck: "UpperChest", Head: "Neck", Jaw: "Head",
};
for (const s of ["Left", "Right"]) {
  Object.assign(unityParent, {
    [`${s}Shoulder`]: "UpperChest", [`${s}UpperArm`]: `${s}Shoulder`, [`${s}LowerArm`]: `${s}UpperArm`,
    [`${s}Hand`]: `${s}LowerArm`, [`${s}UpperLeg`]: "Hips", [`${s}LowerLeg`]: `${s}UpperLeg`,
    [`${s}Foot`]: `${s}LowerLeg`, [`${s}Toes`]: `${s}Foot`,
  });
  for (const f of ["Thumb", "Index", "Middle", "Ring", "Little"]) {
    unityParent[`${s}${f}Proximal`] = `${s}Hand`;
    unityParent[`${s}${f}Intermediate`] = `${s}${f}Proximal`;
    unityParent[`${s}${f}Distal`] = `${s}${f}Intermediate`;
  }
}
// VRM 1.0 names -> Unity's (the thumb's three bones are named differently).
const vrm1ToUnity = {};
for (const u of Object.keys(unityParent)) {
  let v = u[0].toLowerCase() + u.slice(1);
  v = v.replace(/Thumb(Proximal|Intermediate|Distal)$/, (_, p) => `Thumb${{ Proximal: "Metacarpal", Intermediate: "Proximal", Distal: "Distal" }[p]}`);
  vrm1ToUnity[v] = u;
}
const toUnity = (name) => (opt.bones === "vrm1" ? vrm1ToUnity[name] : unityParent[name] !== undefined ? name : undefined);

// The SMPL-X joints (BEAT2 BVH) that play humanoid bones. (kinemo sends no
// eye bones: its humanoid roles have none; docs/vmc.md.)
const smplxToUnity = { pelvis: "Hips", spine1: "Spine", spine2: "Chest", spine3: "UpperChest", neck: "Neck", head: "Head", jaw: "Jaw" };
for (const [s, S] of [["left", "Left"], ["right", "Right"]]) {
  Object.assign(smplxToUnity, {
    [`${s}_collar`]: `${S}Shoulder`, [`${s}_shoulder`]: `${S}UpperArm`, [`${s}_elbow`]: `${S}LowerArm`,
    [`${s}_wrist`]: `${S}Hand`, [`${s}_hip`]: `${S}UpperLeg`, [`${s}_knee`]: `${S}LowerLeg`,
    [`${s}_ankle`]: `${S}Foot`, [`${s}_foot`]: `${S}Toes`,
  });
  for (const [f, F] of [["thumb", "Thumb"], ["index", "Index"], ["middle", "Middle"], ["ring", "Ring"], ["pinky", "Little"]]) {
    ["Proximal", "Intermediate", "Distal"].forEach((p, k) => (smplxToUnity[`${s}_${f}${k + 1}`] = `${S}${F}${p}`));
  }
}

// ---- the BVH ----------------------------------------------------------------
function readBvh(text) {
  const tokens = text.split(/\s+/).filter(Boolean);
  let i = 0;
  const joints = [];
  const stack = [];
  let pendingEnd = false;
  while (tokens[i] !== "MOTION") {
    const t = tokens[i++];
    if (t === "ROOT" || t === "JOINT") {
      joints.push({ name: tokens[i++], parent: stack.length ? stack[stack.length - 1] : -1, offset: null, channels: [] });
    } else if (t === "End") {
      i++; // Site
      pendingEnd = true;
    } else if (t === "{") {
      stack.push(pendingEnd ? -2 : joints.length - 1);
    } else if (t === "}") {
      stack.pop();
      pendingEnd = false;
    } else if (t === "OFFSET") {
      const o = [Number(tokens[i]), Number(tokens[i + 1]), Number(tokens[i + 2])];
      i += 3;
      if (!pendingEnd) joints[joints.length - 1].offset = o;
    } else if (t === "CHANNELS") {
      const n = Number(tokens[i++]);
      joints[joints.length - 1].channels = tokens.slice(i, i + n);
      i += n;
    }
  }
  i++; // MOTION
  i++; // Frames:
  const frames = Number(tokens[i++]);
  i += 2; // Frame Time:
  const frameTime = Number(tokens[i++]);
  const width = joints.reduce((n, j) => n + j.channels.length, 0);
  const values = [];
  for (let f = 0; f < frames; f++) values.push(tokens.slice(i + f * width, i + (f + 1) * width).map(Number));
  return { joints, frameTime, values };
}
const axisQuat = (axis, deg) => {
  const h = (deg * Math.PI) / 360;
  const q = [0, 0, 0, Math.cos(h)];
  q["XYZ".indexOf(axis)] = Math.sin(h);
  return q;
};
// World positions of every joint in one frame (file units).
function bvhWorld(bvh, row) {
  const pos = [], rot = [];
  let c = 0;
  bvh.joints.forEach((j, k) => {
    let local = j.offset.slice();
    let r = [0, 0, 0, 1];
    for (const ch of j.channels) {
      const v = row[c++];
      if (ch.endsWith("position")) local["XYZ".indexOf(ch[0])] = v;
      else r = qmul(r, axisQuat(ch[0], v));
    }
    if (j.parent < 0) {
      pos[k] = local;
      rot[k] = r;
    } else {
      pos[k] = add(pos[j.parent], qrot(rot[j.parent], local));
      rot[k] = qmul(rot[j.parent], r);
    }
  });
  return pos;
}

const bvh = readBvh(readFileSync(opt.bvh, "utf8"));
const index = Object.fromEntries(bvh.joints.map((j, k) => [j.name, k]));
const restPos = [];
bvh.joints.forEach((j, k) => (restPos[k] = j.parent < 0 ? j.offset : add(restPos[j.parent], j.offset)));
// The file's unit: the nearest of m, dm, inch, cm, mm to a 0.8 m hip-knee-ankle leg.
const legOf = (s) => norm(bvh.joints[index[`${s}_knee`]].offset) + norm(bvh.joints[index[`${s}_ankle`]].offset);
const leg = (legOf("left") + legOf("right")) / 2;
const units = [1, 0.1, 0.0254, 0.01, 0.001];
const fileUnit = units.reduce((best, u) => (Math.abs(Math.log(u / (0.8 / leg))) < Math.abs(Math.log(best / (0.8 / leg))) ? u : best));
// The receiver's frame: x = the rest pose's right -> left hip line made
// level (the character's left), y up, z = x × y; Unity mirrors x.
let left = sub(restPos[index.left_hip], restPos[index.right_hip]);
left = [left[0], 0, left[2]];
const ln = norm(left);
left = [left[0] / ln, 0, left[2] / ln];
const fwd = [-left[2], 0, left[0]]; // left × up
const toReceiver = (p) => [-(left[0] * p[0] + left[2] * p[2]) * mpu, p[1] * mpu, (fwd[0] * p[0] + fwd[2] * p[2]) * mpu];

// The source drives a humanoid bone when its joint's channels move.
const driven = new Set();
{
  let c = 0;
  bvh.joints.forEach((j) => {
    const n = j.channels.length;
    let moves = false;
    for (let k = c; k < c + n && !moves; k++) {
      const first = bvh.values[0][k];
      moves = bvh.values.some((row) => Math.abs(row[k] - first) > 1e-9);
    }
    if (moves && smplxToUnity[j.name]) driven.add(smplxToUnity[j.name]);
    c += n;
  });
}

// ---- the recording: frames ------------------------------------------------------
const recording = JSON.parse(readFileSync(opt.recording, "utf8"));
const kinemo = JSON.parse(readFileSync(opt.kinemo, "utf8"));
// Lengths in metres: the stream's own scale (its header's meters_per_unit,
// which kinemo reports), a plausible one for these legs.
const mpu = kinemo.vmc_meters_per_unit;
if (!(mpu > 0.85 * fileUnit && mpu < 1.15 * fileUnit)) fail(`vmc_meters_per_unit ${mpu}, the legs say about ${fileUnit}`);
if (recording.decode_errors > 0) fail(`${recording.decode_errors} datagrams the receiver could not decode`);
if (recording.datagrams.some((d) => !d.bundle)) fail("a datagram that is not an OSC bundle");
const frames = [];
let cur = { bones: {}, blends: {}, blendOrder: [], applied: false, root: null, ok: null, arrival: [] };
for (const d of recording.datagrams) {
  for (const m of d.messages) {
    const [address, ...a] = m;
    cur.arrival.push(d.t_ms);
    if (address === "/VMC/Ext/Root/Pos") cur.root = a;
    else if (address === "/VMC/Ext/Bone/Pos") {
      const u = toUnity(a[0]);
      if (u === undefined) fail(`unknown ${opt.bones} bone name '${a[0]}'`);
      else cur.bones[u] = { p: a.slice(1, 4), q: a.slice(4, 8), t_ms: d.t_ms };
    } else if (address === "/VMC/Ext/Blend/Val") {
      if (cur.applied) fail("Blend/Val after Blend/Apply in one frame");
      cur.blends[a[0]] = a[1];
      cur.blendOrder.push(a[0]);
    } else if (address === "/VMC/Ext/Blend/Apply") cur.applied = true;
    else if (address === "/VMC/Ext/OK") cur.ok = a;
    else if (address === "/VMC/Ext/T") {
      cur.t = a[0];
      frames.push(cur);
      cur = { bones: {}, blends: {}, blendOrder: [], applied: false, root: null, ok: null, arrival: [] };
    } else fail(`unexpected address ${address}`);
  }
}
if (cur.arrival.length > 0) fail("messages after the last /VMC/Ext/T");
if (frames.length === 0) fail("no frames received");

// ---- per frame: completeness, wrists ---------------------------------------------
const blendNames = {
  vrm0: ["A", "I", "U", "E", "O", "Blink", "Blink_L", "Blink_R", "Joy", "Angry", "Sorrow", "Fun", "Surprised"],
  vrm1: ["aa", "ih", "ou", "ee", "oh", "blink", "blinkLeft", "blinkRight", "happy", "angry", "sad", "relaxed", "surprised"],
}[opt.bones === "vrm1" ? "vrm1" : "vrm0"];
let worst = 0, sum = 0, samples = 0, faceFrames = 0;
const missing = new Set();
for (const fr of frames) {
  if (!fr.root || fr.root[0] !== "root" || fr.root.length < 8) fail(`frame at ${fr.t}: no /VMC/Ext/Root/Pos "root"`);
  if (!fr.ok || fr.ok[0] !== 1) fail(`frame at ${fr.t}: no /VMC/Ext/OK 1`);
  for (const b of driven) if (!fr.bones[b]) missing.add(b);
  const hasFace = fr.blendOrder.length > 0;
  if (hasFace) {
    faceFrames++;
    if (!fr.applied) fail(`frame at ${fr.t}: Blend/Val without Blend/Apply`);
    for (const n of blendNames) if (!(n in fr.blends)) fail(`frame at ${fr.t}: no blend shape ${n}`);
    for (const [n, w] of Object.entries(fr.blends)) if (!(w >= 0 && w <= 1)) fail(`frame at ${fr.t}: ${n} = ${w}`);
  }
  // Forward kinematics: the root's pose, then each bone under its parent.
  const world = {};
  const rootP = fr.root.slice(1, 4), rootQ = fr.root.slice(4, 8);
  const place = (name) => {
    if (world[name]) return world[name];
    const b = fr.bones[name];
    let p = unityParent[name];
    while (p && !fr.bones[p]) p = unityParent[p];
    const parent = p ? place(p) : { p: rootP, q: rootQ };
    world[name] = { p: add(parent.p, qrot(parent.q, b.p)), q: qmul(parent.q, b.q) };
    return world[name];
  };
  const f = Math.round(fr.t / bvh.frameTime);
  if (f < 0 || f >= bvh.values.length || Math.abs(f * bvh.frameTime - fr.t) > 1e-3) {
    fail(`frame at ${fr.t}: no BVH frame at that time`);
    continue;
  }
  const src = bvhWorld(bvh, bvh.values[f]);
  for (const [joint, bone] of [["left_wrist", "LeftHand"], ["right_wrist", "RightHand"]]) {
    if (!fr.bones[bone]) continue;
    const e = norm(sub(place(bone).p, toReceiver(src[index[joint]])));
    worst = Math.max(worst, e);
    sum += e;
    samples++;
  }
}
if (missing.size > 0) fail(`bones the source drives that some frames lack: ${[...missing].join(" ")}`);
const maxErr = Number(opt["max-wrist-error-m"]);
if (!(worst <= maxErr)) fail(`wrist path off by up to ${(worst * 100).toFixed(2)} cm (> ${maxErr * 100} cm)`);
if (samples === 0) fail("no wrist samples");
// The blend shapes against the faces kinemo received (--visemes).
let faceWorst = 0, faceCompared = 0, mouthOpen = 0;
if (opt.visemes) {
  const v = JSON.parse(readFileSync(opt.visemes, "utf8"));
  const ovr = (fr, name) => fr.ovr[v.ovr_visemes.indexOf(name)];
  const expressionShape = opt.bones === "vrm1"
    ? { happy: "happy", angry: "angry", sad: "sad", surprised: "surprised" }
    : { happy: "Joy", angry: "Angry", sad: "Sorrow", surprised: "Surprised" };
  const [A, I, U, E, O, Blink, BlinkL, BlinkR, , , , Fun] = blendNames;
  for (const fr of frames) {
    if (fr.blendOrder.length === 0) continue;
    const k = Math.round(fr.t / v.frame_time_s);
    const face = v.frames[k];
    if (!face || Math.abs(face.time_s - fr.t) > 1e-3) {
      fail(`frame at ${fr.t}: no face at that time in ${opt.visemes}`);
      continue;
    }
    const both = Math.min(face.blink_left, face.blink_right);
    // docs/retarget.md "Many-to-one: OVR -> five vowels", all x (1 - PP);
    // the vowel visemes opened with the jaw ("Vowels open as far as the
    // jaw": x clamp(jaw_deg / 2.65, 0, 1)).
    const open = Math.min(1, Math.max(0, face.jaw_deg / 2.65));
    const input = (name) => ovr(face, name) * (["aa", "E", "ih", "oh", "ou"].includes(name) ? open : 1);
    const vowel = (terms) => {
      let w = 0;
      for (const [name, c] of Object.entries(terms)) w += c * input(name);
      return Math.min(1, Math.max(0, w)) * (1 - ovr(face, "PP"));
    };
    const want = {
      [A]: vowel({ aa: 1, kk: 0.4, DD: 0.3, TH: 0.2, nn: 0.2 }),
      [I]: vowel({ ih: 1, SS: 0.6, FF: 0.3, TH: 0.3, DD: 0.3, CH: 0.3, nn: 0.3 }),
      [U]: vowel({ ou: 1, CH: 0.5, RR: 0.4 }),
      [E]: vowel({ E: 1, kk: 0.2 }),
      [O]: vowel({ oh: 1, RR: 0.3 }),
      [Blink]: both, [BlinkL]: face.blink_left - both, [BlinkR]: face.blink_right - both, [Fun]: 0,
    };
    for (const [e, shape] of Object.entries(expressionShape)) want[shape] = face.expression === e ? face.expression_weight : 0;
    for (const [name, w] of Object.entries(want)) faceWorst = Math.max(faceWorst, Math.abs(fr.blends[name] - w));
    if (Math.max(fr.blends[A], fr.blends[I], fr.blends[U], fr.blends[E], fr.blends[O]) > 0.3) mouthOpen++;
    faceCompared++;
  }
  // The file rounds to 4 decimals; the weights travel as float32.
  if (!(faceWorst <= 2e-4)) fail(`blend shapes differ from the faces received by up to ${faceWorst}`);
}
if (opt.face === "required" && faceFrames !== frames.length) fail(`${faceFrames} of ${frames.length} frames carry the face`);
if (opt.face === "absent" && faceFrames !== 0) fail(`${faceFrames} frames carry blend shapes, none expected`);
if (opt.face === "auto" && faceFrames !== 0 && faceFrames !== frames.length) {
  fail(`${faceFrames} of ${frames.length} frames carry the face`);
}

// ---- rates: bone messages per second per bone (the receiver's clock) -------------
// During speech: the frames up to 0.5 s before the audio's end (the last
// ones come with the stream's close, not at the audio's pace).
let minRate = Infinity, minWindow = Infinity;
const speechEnd = kinemo.audio_s - 0.5;
for (const b of driven) {
  const times = frames.filter((fr) => fr.bones[b] && fr.t <= speechEnd).map((fr) => fr.bones[b].t_ms);
  if (times.length < 2) continue;
  const span_s = (times[times.length - 1] - times[0]) / 1000;
  minRate = Math.min(minRate, (times.length - 1) / span_s);
  // The fewest messages in any 1 s window from the first message on.
  for (let i = 0, j = 0; i < times.length && times[i] + 1000 <= times[times.length - 1]; i++) {
    while (j < times.length && times[j] < times[i] + 1000) j++;
    minWindow = Math.min(minWindow, j - i);
  }
}
if (!(minRate >= 29)) fail(`bone messages per second per bone: ${minRate.toFixed(2)} (< 29)`);
for (const k of ["vmc_packets", "vmc_bones", "vmc_blendshapes"]) if (!(k in kinemo)) fail(`kinemo --json lacks ${k}`);
if (kinemo.vmc_bones !== driven.size) fail(`kinemo says ${kinemo.vmc_bones} bones, the source drives ${driven.size}`);
if (kinemo.vmc_packets !== recording.datagrams.length) {
  fail(`kinemo sent ${kinemo.vmc_packets} packets, ${recording.datagrams.length} arrived (loopback loses none)`);
}
if (frames.length !== kinemo.vmc_frames) fail(`${frames.length} frames received, kinemo sent ${kinemo.vmc_frames}`);

const report = {
  frames: frames.length, datagrams: recording.datagrams.length, bones_driven: driven.size,
  wrist_max_error_cm: worst * 100, wrist_mean_error_cm: (sum / samples) * 100,
  bone_messages_per_s_min: minRate, bone_messages_min_in_1s: minWindow, face_frames: faceFrames,
  blendshapes_per_face_frame: faceFrames > 0 ? frames.reduce((n, fr) => n + fr.blendOrder.length, 0) / faceFrames : 0,
  face_frames_compared: faceCompared, blend_max_diff: faceWorst, frames_mouth_open: mouthOpen,
  meters_per_unit: mpu, file_unit: fileUnit, vmc_lag_p50_ms: kinemo.vmc_lag_p50_ms, vmc_lag_p99_ms: kinemo.vmc_lag_p99_ms,
  motion_lag_p50_ms: kinemo.motion_lag_p50_ms, motion_lag_p99_ms: kinemo.motion_lag_p99_ms,
};
console.log(JSON.stringify(report));
if (failures.length > 0) {
  for (const f of [...new Set(failures)].slice(0, 20)) console.error(`FAIL: ${f}`);
  process.exit(1);
}
