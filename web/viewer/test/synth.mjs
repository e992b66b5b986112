// A synthetic recording with known poses for the viewer's tests (and for trying the viewer without
// a C++ build): the real humanoid geometry (data/humanoid.json, forward kinematics of its rest
// pose) translated along a straight line, a chair of boxes, targets.
//   node test/synth.mjs OUT.rec   writes the file
import { readFileSync, writeFileSync } from 'node:fs';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';
import { createCodec } from '../src/reader.js';

const here = dirname(fileURLToPath(import.meta.url));
export const REPO = join(here, '..', '..', '..');
export const PROTO_TEXT = readFileSync(join(REPO, 'common', 'proto', 'recording.proto'), 'utf8');

// quaternions w x y z
export function qmul(a, b) {
  return [
    a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
    a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
    a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
    a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
  ];
}
export function qrot(q, v) {
  const p = qmul(qmul(q, [0, ...v]), [q[0], -q[1], -q[2], -q[3]]);
  return [p[1], p[2], p[3]];
}
const qnorm = (q) => { const n = Math.hypot(...q); return q.map((c) => c / n); };
export const yawQuat = (yaw) => [Math.cos(yaw / 2), 0, 0, Math.sin(yaw / 2)];
export const pitchQuat = (a) => [Math.cos(a / 2), 0, Math.sin(a / 2), 0];
const add = (a, b) => a.map((v, i) => v + b[i]);

// Header bodies (RecBody) and the rest pose's body frames relative to the root (torso).
export function loadHumanoid() {
  const h = JSON.parse(readFileSync(join(REPO, 'data', 'humanoid.json'), 'utf8'));
  const index = new Map(h.bodies.map((b, i) => [b.name, i]));
  const bodies = h.bodies.map((b) => ({
    name: b.name,
    parent: b.parent ? index.get(b.parent) : -1,
    geoms: b.geoms.map((g) => (g.type === 'sphere'
      ? { type: 'sphere', from: g.pos, to: g.pos, radius: g.radius }
      : { type: 'capsule', from: g.fromto.slice(0, 3), to: g.fromto.slice(3, 6), radius: g.radius })),
  }));
  const rest = [];  // [{p, q}] relative to the torso frame
  h.bodies.forEach((b, i) => {
    if (!b.parent) { rest[i] = { p: [0, 0, 0], q: [1, 0, 0, 0] }; return; }
    const par = rest[index.get(b.parent)];
    rest[i] = { p: add(par.p, qrot(par.q, b.pos)), q: qnorm(qmul(par.q, b.quat)) };
  });
  // lowest point of the rest pose below the torso: standing height of the torso frame
  let minZ = Infinity;
  bodies.forEach((b, i) => b.geoms.forEach((g) => {
    for (const pt of [g.from, g.to]) minZ = Math.min(minZ, add(rest[i].p, qrot(rest[i].q, pt))[2] - g.radius);
  }));
  return { bodies, rest, torsoHeight: -minZ, jointNames: h.observation_order || [] };
}

// World body poses of the rest pose with the torso frame at `root` rotated by `rootQuat`, the body
// pivoting about the point between the feet (so a pitched body "falls" about its feet).
export function posePoints(hum, root, rootQuat) {
  const pos = [], quat = [];
  const pivot = [0, 0, -hum.torsoHeight];
  hum.rest.forEach((r) => {
    const p = add(qrot(rootQuat, add(r.p, pivot.map((v) => -v))), add(root, pivot));
    pos.push(...p);
    quat.push(...qnorm(qmul(rootQuat, r.q)));
  });
  return { pos, quat };
}

export const CHAIR = {
  name: 'synthetic_chair',
  boxes: [
    { role: 'seat', min: [-0.23, -0.23, 0.40], max: [0.23, 0.23, 0.47] },
    { role: 'leg', min: [0.17, 0.17, 0], max: [0.22, 0.22, 0.40] },
    { role: 'leg', min: [0.17, -0.22, 0], max: [0.22, -0.17, 0.40] },
    { role: 'leg', min: [-0.22, 0.17, 0], max: [-0.17, 0.22, 0.40] },
    { role: 'leg', min: [-0.22, -0.22, 0], max: [-0.17, -0.17, 0.40] },
    { role: 'backrest', min: [-0.27, -0.23, 0.47], max: [-0.21, 0.23, 0.98] },
  ],
  seat_target: [0.0, 0.0, 0.56],
};

// A mesh chair (as a recording carries one: triangles in the chair frame): a 0.5 m seat block
// 0.45 m high and a backrest slab, 24 triangles.
function blockTriangles(min, max, base) {
  const v = [];
  for (let k = 0; k < 8; k++) v.push((k & 1) ? max[0] : min[0], (k & 2) ? max[1] : min[1], (k & 4) ? max[2] : min[2]);
  const quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
  const t = [];
  for (const q of quads) t.push(base + q[0], base + q[1], base + q[2], base + q[0], base + q[2], base + q[3]);
  return { v, t };
}
const seatBlock = blockTriangles([-0.25, -0.25, 0], [0.25, 0.25, 0.45], 0);
const backSlab = blockTriangles([-0.33, -0.25, 0], [-0.25, 0.25, 0.95], 8);
export const MESH_CHAIR = {
  name: 'synthetic_mesh_chair',
  boxes: [],
  seat_target: [0.0, 0.0, 0.45],
  mesh_vertices: [...seatBlock.v, ...backSlab.v],
  mesh_triangles: [...seatBlock.t, ...backSlab.t],
  source: 'synthetic',
};

// Episode 0 ("success"): the humanoid slides from (x0, 0) to (x1, 0) over `frames` frames (known
// pelvis path), a chair at `chairPos` with yaw `chairYaw`, a walk target and a meta target.
// Episode 1 ("fell"): pitches forward about its feet, a mesh chair elsewhere. Episode 2 ("time_limit"):
// no chair, turning in place.
export const SYNTH = {
  frames: 91, x0: 0, x1: 1.5, chairPos: [1.0, 1.6, 0], chairYaw: -0.7,
  walkTarget: [3, 0], metaTarget: [2, 1], controlDt: 1 / 60,
};

export function makeSyntheticRecording(opts = {}) {
  const s = { ...SYNTH, ...opts };
  const hum = loadHumanoid();
  const h = hum.torsoHeight;
  const frame = (k, pose, extra) => ({
    step: k,
    time_s: k * s.controlDt,
    body_pos: pose.pos,
    body_quat: pose.quat,
    q: hum.jointNames.map(() => 0),
    chair_pos: [], chair_quat: [], walk_target: [], meta_target: [],
    active_subtask: -1, meta_step: -1,
    foot_contact_right: true, foot_contact_left: true, pelvis_seat_contact: false,
    reward: k === 0 ? 0 : 1,
    reward_terms: k === 0 ? {} : { alive: 0.5, progress: 0.5 },
    ...extra,
  });
  const ep0 = [];
  for (let k = 0; k < s.frames; k++) {
    const x = s.x0 + (s.x1 - s.x0) * k / (s.frames - 1);
    ep0.push(frame(k, posePoints(hum, [x, 0, h], [1, 0, 0, 0]), {
      chair_pos: s.chairPos, chair_quat: yawQuat(s.chairYaw),
      walk_target: s.walkTarget, meta_target: s.metaTarget,
      active_subtask: k < s.frames / 2 ? 3 : 2, meta_step: k < s.frames / 2 ? 0 : 1,
      foot_contact_right: k % 20 < 10, foot_contact_left: k % 20 >= 10,
      pelvis_seat_contact: k === s.frames - 1,
    }));
  }
  const ep1 = [];
  for (let k = 0; k < 40; k++) {
    ep1.push(frame(k, posePoints(hum, [-1, -1, h], pitchQuat(1.4 * k / 39)), {
      chair_pos: [1.5, -1.5, 0], chair_quat: yawQuat(2.5), walk_target: s.walkTarget,
      reward: k === 0 ? 0 : -0.1,
    }));
  }
  const ep2 = [];
  for (let k = 0; k < 30; k++) {
    ep2.push(frame(k, posePoints(hum, [0.5, 0.5, h], yawQuat(k * 0.05)), { active_subtask: 0, meta_step: 3 }));
  }
  return {
    format_version: 1,
    perch_version: 'synthetic',
    task: 'sit',
    model: 'models/sit/policy.bin (synthetic)',
    config_json: '{}',
    seed: 7,
    stochastic: false,
    control_dt: s.controlDt,
    bodies: hum.bodies,
    joint_names: hum.jointNames,
    episodes: [
      { index: 0, seed: 100, outcome: 'success', success: true, fell: false, chair: CHAIR, frames: ep0 },
      { index: 1, seed: 101, outcome: 'fell', success: false, fell: true, chair: MESH_CHAIR, frames: ep1 },
      { index: 2, seed: '12345678901234567891', outcome: 'time_limit', success: false, fell: false, frames: ep2 },
    ],
  };
}

export function writeSyntheticFile(path, opts) {
  const codec = createCodec(PROTO_TEXT);
  const bytes = codec.encodeRecordingFile(makeSyntheticRecording(opts));
  writeFileSync(path, bytes);
  return bytes;
}

if (process.argv[1] && fileURLToPath(import.meta.url) === process.argv[1]) {
  const out = process.argv[2];
  if (!out) { console.error('usage: node test/synth.mjs OUT.rec'); process.exit(2); }
  const bytes = writeSyntheticFile(out);
  console.log(`wrote ${out} (${bytes.length} bytes)`);
}
