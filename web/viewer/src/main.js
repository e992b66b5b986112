// Perch recording viewer (docs/viewer.md): replays `perch eval --record` files in three.js.
//
// Coordinates: a recording is z-up (x forward of the reset heading, y left, ground z = 0).
// three.js is y-up. All recorded geometry lives in one group `world` rotated -90 deg about x, so
// inside it the recording's numbers are used as they are; a recording point (x, y, z) is drawn
// at three.js (x, z, -y) (a proper rotation: handedness and angles are kept).
import * as THREE from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';
import protoText from '../../../common/proto/recording.proto';
import { createCodec, subtaskName } from './reader.js';

const COLORS = {
  background: 0xcfd8e3,
  ground: 0xa3a39b,
  grid: 0x6f6f68,
  gridMinor: 0x8f8f88,
  body: 0xe8893a,
  pelvis: 0xd9702a,
  chair: 0x3f6fb5,
  seatTarget: 0x1f9e4a,
  walkTarget: 0x19a34a,
  metaTarget: 0xb23cc4,
  trail: 0xc0282d,
};
const SPEEDS = [0.25, 0.5, 1, 2, 4];

const codec = createCodec(protoText);
const $ = (id) => document.getElementById(id);
const ui = {
  stage: $('stage'), hud: $('hud'), status: $('status'), error: $('error'),
  file: $('file'), episode: $('episode'), prevEp: $('prev-ep'), nextEp: $('next-ep'),
  play: $('play'), speed: $('speed'), scrub: $('scrub'), frameLabel: $('frame-label'),
  follow: $('follow'), trail: $('trail'),
};

// ---- state exposed to tests (window.perchViewer) -----------------------------------------------
const api = {
  loaded: false,       // a recording is loaded and drawn
  error: null,         // the last load error (string), null when none
  name: null,          // file name / URL of the loaded recording
  episode: 0,          // index into the recording's episodes (not RecEpisode.index)
  frame: 0,            // current frame of that episode
  numFrames: 0,
  numEpisodes: 0,
  playing: false,
  speed: 1,
  follow: false,
  webgl: false,
};
window.perchViewer = api;

// ---- three.js scene -----------------------------------------------------------------------------
let renderer;
try {
  renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
  api.webgl = true;
} catch (e) {
  showError(`WebGL is not available in this browser: ${e.message}`);
}
const scene = new THREE.Scene();
scene.background = new THREE.Color(COLORS.background);
scene.fog = new THREE.Fog(COLORS.background, 30, 90);
const camera = new THREE.PerspectiveCamera(45, 1, 0.05, 300);
camera.position.set(3, 2, 3);
let controls = null;
if (renderer) {
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  renderer.shadowMap.enabled = true;
  renderer.shadowMap.type = THREE.PCFShadowMap;
  ui.stage.prepend(renderer.domElement);
  controls = new OrbitControls(camera, renderer.domElement);
  controls.target.set(0, 0.8, 0);
  controls.addEventListener('change', () => { dirty = true; });
}

scene.add(new THREE.HemisphereLight(0xf4f7ff, 0x6b6458, 1.6));
const sun = new THREE.DirectionalLight(0xffffff, 1.8);
sun.castShadow = true;
sun.shadow.mapSize.set(1024, 1024);
sun.shadow.camera.left = -4; sun.shadow.camera.right = 4;
sun.shadow.camera.top = 4; sun.shadow.camera.bottom = -4;
sun.shadow.camera.near = 0.5; sun.shadow.camera.far = 30;
sun.shadow.bias = -0.0005;
scene.add(sun, sun.target);
const SUN_OFFSET = new THREE.Vector3(3, 8, 4);  // three.js coords, from the light's target

const world = new THREE.Group();  // recording (z-up) frame
world.rotation.x = -Math.PI / 2;
scene.add(world);

// ground: a plane at z = 0 with a grid texture: 1 m cells, 0.5 m minor lines (a texture rather than
// GL lines: long lines crossing the near plane are dropped by some software GL drivers)
function gridTexture() {
  const n = 256;
  const c = document.createElement('canvas');
  c.width = c.height = n;
  const g = c.getContext('2d');
  const hex = (v) => '#' + v.toString(16).padStart(6, '0');
  g.fillStyle = hex(COLORS.ground);
  g.fillRect(0, 0, n, n);
  g.fillStyle = hex(COLORS.gridMinor);
  g.fillRect(n / 2 - 1, 0, 2, n);
  g.fillRect(0, n / 2 - 1, n, 2);
  g.fillStyle = hex(COLORS.grid);
  g.fillRect(0, 0, 3, n);
  g.fillRect(n - 3, 0, 3, n);
  g.fillRect(0, 0, n, 3);
  g.fillRect(0, n - 3, n, 3);
  const t = new THREE.CanvasTexture(c);
  t.wrapS = t.wrapT = THREE.RepeatWrapping;
  t.colorSpace = THREE.SRGBColorSpace;
  t.anisotropy = renderer ? renderer.capabilities.getMaxAnisotropy() : 1;
  return t;
}
const GROUND_SIZE = 200;  // m, cells of 1 m
const groundTexture = gridTexture();
groundTexture.repeat.set(GROUND_SIZE, GROUND_SIZE);
const ground = new THREE.Mesh(
  new THREE.PlaneGeometry(GROUND_SIZE, GROUND_SIZE),
  new THREE.MeshStandardMaterial({ color: 0xffffff, map: groundTexture, roughness: 1 }));
ground.receiveShadow = true;
world.add(ground);
world.add(new THREE.AxesHelper(0.5));  // recording axes at the origin: x red, y green, z blue

const bodyMaterial = new THREE.MeshStandardMaterial({ color: COLORS.body, roughness: 0.55 });
const pelvisMaterial = new THREE.MeshStandardMaterial({ color: COLORS.pelvis, roughness: 0.55 });
const chairMaterial = new THREE.MeshStandardMaterial({ color: COLORS.chair, roughness: 0.7 });
// Mesh files need not wind their triangles consistently: both sides are drawn.
const chairMeshMaterial = new THREE.MeshStandardMaterial({ color: COLORS.chair, roughness: 0.7, side: THREE.DoubleSide });

let humanoid = null;   // { group, bodies: [THREE.Group], names: Map(name -> index), pelvis }
const chair = new THREE.Group();
world.add(chair);
const seatTarget = new THREE.Mesh(
  new THREE.SphereGeometry(0.03, 12, 8),
  new THREE.MeshBasicMaterial({ color: COLORS.seatTarget, wireframe: true }));

function targetMarker(color) {
  const g = new THREE.Group();
  const mat = new THREE.MeshStandardMaterial({ color, roughness: 0.6 });
  const pole = new THREE.Mesh(new THREE.CylinderGeometry(0.02, 0.02, 1.0, 10), mat);
  pole.rotation.x = Math.PI / 2;  // cylinder axis y -> recording z
  pole.position.z = 0.5;
  const ring = new THREE.Mesh(new THREE.RingGeometry(0.12, 0.18, 32), new THREE.MeshBasicMaterial({ color, side: THREE.DoubleSide }));
  ring.position.z = 0.004;
  const top = new THREE.Mesh(new THREE.SphereGeometry(0.05, 12, 8), mat);
  top.position.z = 1.0;
  g.add(pole, ring, top);
  g.visible = false;
  world.add(g);
  return g;
}
const walkMarker = targetMarker(COLORS.walkTarget);
const metaMarker = targetMarker(COLORS.metaTarget);

const trailGeometry = new THREE.BufferGeometry();
const trail = new THREE.Line(trailGeometry, new THREE.LineBasicMaterial({ color: COLORS.trail }));
trail.frustumCulled = false;
world.add(trail);

// A capsule (segment a-b, radius r) or a sphere (a = b) as a mesh in the body frame.
function geomMesh(geom, material) {
  const a = new THREE.Vector3(...(geom.from.length === 3 ? geom.from : [0, 0, 0]));
  const b = new THREE.Vector3(...(geom.to.length === 3 ? geom.to : a.toArray()));
  const r = geom.radius > 0 ? geom.radius : 0.01;
  const len = a.distanceTo(b);
  let mesh;
  if (geom.type === 'sphere' || len < 1e-6) {
    mesh = new THREE.Mesh(new THREE.SphereGeometry(r, 20, 14), material);
    mesh.position.copy(a);
  } else {
    mesh = new THREE.Mesh(new THREE.CapsuleGeometry(r, len, 6, 16), material);
    mesh.position.copy(a).add(b).multiplyScalar(0.5);
    mesh.quaternion.setFromUnitVectors(new THREE.Vector3(0, 1, 0), b.clone().sub(a).normalize());
  }
  mesh.castShadow = true;
  mesh.receiveShadow = true;
  return mesh;
}

function disposeTree(obj) {
  obj.traverse((o) => { if (o.geometry) o.geometry.dispose(); });
}

function buildHumanoid(bodies) {
  if (humanoid) { world.remove(humanoid.group); disposeTree(humanoid.group); }
  const group = new THREE.Group();
  const names = new Map();
  const objs = bodies.map((b, i) => {
    names.set(b.name, i);
    const g = new THREE.Group();
    g.name = b.name;
    const mat = b.name === 'pelvis' ? pelvisMaterial : bodyMaterial;
    for (const geom of b.geoms) g.add(geomMesh(geom, mat));
    group.add(g);
    return g;
  });
  world.add(group);
  const pelvis = names.has('pelvis') ? names.get('pelvis') : 0;
  humanoid = { group, bodies: objs, names, pelvis };
}

function buildChair(ep) {
  disposeTree(chair);
  chair.clear();
  const c = ep.chair;
  const hasMesh = c && c.mesh_triangles.length > 0;
  if (!c || (c.boxes.length === 0 && !hasMesh)) return false;
  if (hasMesh) {
    // A mesh chair: its triangles travel in the recording (the mesh file is not needed).
    const geo = new THREE.BufferGeometry();
    geo.setAttribute('position', new THREE.Float32BufferAttribute(c.mesh_vertices, 3));
    geo.setIndex(c.mesh_triangles);
    geo.computeVertexNormals();
    const m = new THREE.Mesh(geo, chairMeshMaterial);
    m.name = 'mesh';
    m.castShadow = true;
    m.receiveShadow = true;
    chair.add(m);
  }
  for (const box of c.boxes) {
    if (box.min.length !== 3 || box.max.length !== 3) continue;
    const size = box.max.map((v, i) => Math.max(1e-4, v - box.min[i]));
    const m = new THREE.Mesh(new THREE.BoxGeometry(...size), chairMaterial);
    m.position.set(...box.min.map((v, i) => 0.5 * (v + box.max[i])));
    m.name = box.role;
    m.castShadow = true;
    m.receiveShadow = true;
    chair.add(m);
  }
  if (c.seat_target.length === 3) {
    seatTarget.position.set(...c.seat_target);
    chair.add(seatTarget);
  }
  return true;
}

// ---- recording state -----------------------------------------------------------------------------
let rec = null;         // decoded Recording (plain object)
let ep = null;          // current episode
let hasChair = false;
let dirty = true;
let frameFloat = 0;     // playback position in frames
let returns = [];       // cumulative reward per frame of the current episode

function setLoaded(recording, name) {
  rec = recording;
  api.loaded = true;
  api.error = null;
  api.name = name;
  api.numEpisodes = rec.episodes.length;
  ui.error.hidden = true;
  ui.status.hidden = true;
  buildHumanoid(rec.bodies);
  ui.episode.innerHTML = '';
  rec.episodes.forEach((e, i) => {
    const opt = document.createElement('option');
    opt.value = String(i);
    opt.textContent = `episode ${e.index}: ${e.outcome || '?'} (${e.frames.length} frames)`;
    ui.episode.append(opt);
  });
  document.title = `Perch viewer: ${name}`;
  if (rec.episodes.length === 0) {
    showError(`${name}: the recording has no episodes`);
    return;
  }
  selectEpisode(0);
}

function selectEpisode(i) {
  if (!rec || rec.episodes.length === 0) return;
  i = Math.max(0, Math.min(rec.episodes.length - 1, i | 0));
  api.episode = i;
  ep = rec.episodes[i];
  api.numFrames = ep.frames.length;
  ui.episode.value = String(i);
  ui.scrub.max = String(Math.max(0, ep.frames.length - 1));
  hasChair = buildChair(ep);
  // pelvis trail and cumulative reward of the whole episode
  const n = ep.frames.length;
  const pos = new Float32Array(Math.max(1, n) * 3);
  const p = humanoid.pelvis;
  returns = new Array(n);
  let sum = 0;
  ep.frames.forEach((f, k) => {
    pos[3 * k] = f.body_pos[3 * p];
    pos[3 * k + 1] = f.body_pos[3 * p + 1];
    pos[3 * k + 2] = f.body_pos[3 * p + 2];
    sum += f.reward;
    returns[k] = sum;
  });
  trailGeometry.setAttribute('position', new THREE.BufferAttribute(pos, 3));
  trailGeometry.setDrawRange(0, 0);
  fitCamera();
  frameFloat = 0;
  if (n === 0) {
    ui.hud.textContent = `episode ${ep.index} (${i + 1}/${rec.episodes.length}) ${ep.outcome}: no frames`;
    ui.frameLabel.textContent = '0 / 0';
    humanoid.group.visible = chair.visible = false;
    dirty = true;
    return;
  }
  humanoid.group.visible = true;
  applyFrame(0);
}

// Places the camera to see the whole episode (pelvis path and chair) from the front right.
function fitCamera() {
  const box = new THREE.Box3();
  const p = humanoid.pelvis;
  for (const f of ep.frames) {
    box.expandByPoint(new THREE.Vector3(f.body_pos[3 * p], f.body_pos[3 * p + 1], 0));
    box.expandByPoint(new THREE.Vector3(f.body_pos[3 * p], f.body_pos[3 * p + 1], 1.5));
    if (f.chair_pos.length === 3) box.expandByPoint(new THREE.Vector3(f.chair_pos[0], f.chair_pos[1], 1.0));
  }
  const f0 = ep.frames[0];
  for (const t of [f0?.walk_target, f0?.meta_target]) {
    if (t && t.length === 2) box.expandByPoint(new THREE.Vector3(t[0], t[1], 0));
  }
  if (box.isEmpty()) box.set(new THREE.Vector3(-1, -1, 0), new THREE.Vector3(1, 1, 1.5));
  const centre = box.getCenter(new THREE.Vector3());
  centre.z = Math.min(centre.z, 0.8);
  const radius = Math.max(1.2, box.getSize(new THREE.Vector3()).length() / 2);
  const dist = Math.max(3, 1.15 * radius / Math.sin(THREE.MathUtils.degToRad(camera.fov / 2)));
  const dir = new THREE.Vector3(0.75, -0.6, 0.32).normalize();  // recording frame: front right, above
  const target = recToThree(centre.x, centre.y, centre.z);
  const eye = recToThree(centre.x + dir.x * dist, centre.y + dir.y * dist, centre.z + dir.z * dist);
  camera.position.copy(eye);
  if (controls) { controls.target.copy(target); controls.update(); } else camera.lookAt(target);
  dirty = true;
}

function recToThree(x, y, z, out = new THREE.Vector3()) {
  return out.set(x, z, -y);
}
function threeToRec(v) {
  return [v.x, -v.z, v.y];
}

const _q = new THREE.Quaternion();
function applyFrame(k) {
  if (!ep || ep.frames.length === 0) return;
  k = Math.max(0, Math.min(ep.frames.length - 1, k | 0));
  api.frame = k;
  const f = ep.frames[k];
  humanoid.bodies.forEach((g, i) => {
    g.position.set(f.body_pos[3 * i], f.body_pos[3 * i + 1], f.body_pos[3 * i + 2]);
    // recording w x y z -> three.js (x, y, z, w)
    _q.set(f.body_quat[4 * i + 1], f.body_quat[4 * i + 2], f.body_quat[4 * i + 3], f.body_quat[4 * i]);
    g.quaternion.copy(_q.lengthSq() > 0 ? _q.normalize() : _q.identity());
  });
  chair.visible = hasChair && f.chair_pos.length === 3;
  if (chair.visible) {
    chair.position.set(f.chair_pos[0], f.chair_pos[1], f.chair_pos[2]);
    const cq = f.chair_quat.length === 4 ? f.chair_quat : [1, 0, 0, 0];
    chair.quaternion.set(cq[1], cq[2], cq[3], cq[0]).normalize();
  }
  walkMarker.visible = f.walk_target.length === 2;
  if (walkMarker.visible) walkMarker.position.set(f.walk_target[0], f.walk_target[1], 0);
  metaMarker.visible = f.meta_target.length === 2;
  if (metaMarker.visible) metaMarker.position.set(f.meta_target[0], f.meta_target[1], 0);
  trailGeometry.setDrawRange(0, k + 1);
  trail.visible = ui.trail.checked;

  world.updateMatrixWorld(true);
  const pelvisWorld = humanoid.bodies[humanoid.pelvis].getWorldPosition(new THREE.Vector3());
  if (api.follow && controls) {
    const delta = new THREE.Vector3(pelvisWorld.x - controls.target.x, 0, pelvisWorld.z - controls.target.z);
    camera.position.add(delta);
    controls.target.add(delta);
    controls.update();
  }
  sun.target.position.set(pelvisWorld.x, 0, pelvisWorld.z);
  sun.position.copy(sun.target.position).add(SUN_OFFSET);

  ui.scrub.value = String(k);
  ui.frameLabel.textContent = `${k + 1} / ${ep.frames.length}`;
  updateHud(f, k);
  dirty = true;
}

function esc(s) {
  return String(s).replace(/[&<>"]/g, (c) => ({ '&': '&amp;', '<': '&lt;', '>': '&gt;', '"': '&quot;' }[c]));
}

function updateHud(f, k) {
  const flag = (on, label) => `<span class="${on ? 'on' : 'off'}">${on ? '\u25cf' : '\u25cb'} ${label}</span>`;
  const lines = [];
  lines.push(`task     ${esc(rec.task || '?')}${rec.stochastic ? ' (stochastic)' : ''}`);
  lines.push(`model    ${esc(rec.model || '?')}`);
  lines.push(`episode  ${ep.index} (${api.episode + 1}/${rec.episodes.length})  <span class="outcome-${esc(ep.outcome)}">${esc(ep.outcome || '?')}</span>  seed ${ep.seed}`);
  lines.push(`time     ${f.time_s.toFixed(3)} s   step ${f.step}`);
  const st = subtaskName(f.active_subtask);
  if (st !== null) lines.push(`subtask  ${st}${f.meta_step >= 0 ? `   meta step ${f.meta_step}` : ''}`);
  lines.push(`contact  ${flag(f.foot_contact_right, 'R foot')} ${flag(f.foot_contact_left, 'L foot')} ${flag(f.pelvis_seat_contact, 'seat')}`);
  lines.push(`reward   ${f.reward.toFixed(4)}   return ${returns[k].toFixed(3)}`);
  const terms = Object.entries(f.reward_terms || {}).sort((a, b) => a[0].localeCompare(b[0]));
  for (const [name, v] of terms) lines.push(`  ${esc(name).padEnd(14)} ${v.toFixed(4)}`);
  ui.hud.innerHTML = lines.join('\n');
  ui.hud.hidden = false;
}

function render() {
  if (!renderer) return;
  renderer.render(scene, camera);
  dirty = false;
}

function resize() {
  if (!renderer) return;
  const w = Math.max(1, ui.stage.clientWidth);
  const h = Math.max(1, ui.stage.clientHeight);
  renderer.setSize(w, h, false);
  camera.aspect = w / h;
  camera.updateProjectionMatrix();
  dirty = true;
}
new ResizeObserver(() => { resize(); render(); }).observe(ui.stage);
resize();

// ---- playback -------------------------------------------------------------------------------------
let lastTime = null;
function tick(now) {
  requestAnimationFrame(tick);
  const dt = lastTime === null ? 0 : Math.min(0.25, (now - lastTime) / 1000);
  lastTime = now;
  if (api.playing && ep) {
    const controlDt = rec.control_dt > 0 ? rec.control_dt : 1 / 60;
    frameFloat += dt * api.speed / controlDt;
    const last = ep.frames.length - 1;
    if (frameFloat >= last) { frameFloat = last; setPlaying(false); }
    if ((frameFloat | 0) !== api.frame) applyFrame(frameFloat | 0);
  }
  if (dirty) render();
}
requestAnimationFrame(tick);

function setPlaying(on) {
  if (on && ep && api.frame >= ep.frames.length - 1) { frameFloat = 0; applyFrame(0); }
  api.playing = !!on && !!ep;
  ui.play.innerHTML = api.playing ? '&#10074;&#10074;' : '&#9654;';
  if (api.playing) frameFloat = api.frame;
}

function seek(episode, frame) {
  if (!rec) throw new Error('no recording loaded');
  if (episode !== undefined && episode !== null && episode !== api.episode) selectEpisode(episode);
  frameFloat = Math.max(0, Math.min(ep.frames.length - 1, frame | 0));
  applyFrame(frameFloat);
  render();
}

function setFollow(on) {
  api.follow = !!on;
  ui.follow.checked = api.follow;
  if (ep) applyFrame(api.frame);
}

function setSpeed(s) {
  api.speed = Number(s) > 0 ? Number(s) : 1;
  const nearest = SPEEDS.reduce((a, b) => (Math.abs(b - api.speed) < Math.abs(a - api.speed) ? b : a));
  ui.speed.value = String(nearest);
}

// ---- loading -------------------------------------------------------------------------------------
function showError(message) {
  api.error = message;
  api.loaded = false;
  ui.error.textContent = `Cannot open the recording.\n${message}`;
  ui.error.hidden = false;
  ui.status.hidden = true;
  console.error(message);
}

function loadBytes(bytes, name) {
  try {
    setPlaying(false);
    setLoaded(codec.readRecording(bytes, name), name);
    render();
  } catch (e) {
    rec = null;
    ep = null;
    Object.assign(api, { numEpisodes: 0, numFrames: 0, episode: 0, frame: 0 });
    ui.episode.innerHTML = '';
    ui.scrub.max = '0';
    ui.frameLabel.textContent = '\u2013';
    ui.hud.hidden = true;
    if (humanoid) humanoid.group.visible = false;
    chair.visible = walkMarker.visible = metaMarker.visible = trail.visible = false;
    render();
    showError(e.message);
  }
  if (humanoid && rec) humanoid.group.visible = true;
}

async function loadUrl(url) {
  const abs = new URL(url, window.location.href);
  ui.status.textContent = `Loading ${url}\u2026`;
  ui.status.hidden = false;
  let res;
  try {
    res = await fetch(abs);
  } catch (e) {
    showError(`${url}: could not fetch (${e.message})`);
    return;
  }
  if (!res.ok) {
    showError(`${url}: could not fetch (HTTP ${res.status} ${res.statusText})`);
    return;
  }
  loadBytes(new Uint8Array(await res.arrayBuffer()), url);
}

async function loadFile(file) {
  ui.status.textContent = `Loading ${file.name}\u2026`;
  ui.status.hidden = false;
  loadBytes(new Uint8Array(await file.arrayBuffer()), file.name);
}

// ---- UI wiring ------------------------------------------------------------------------------------
ui.file.addEventListener('change', () => { if (ui.file.files[0]) loadFile(ui.file.files[0]); });
ui.episode.addEventListener('change', () => { setPlaying(false); selectEpisode(Number(ui.episode.value)); });
ui.prevEp.addEventListener('click', () => { setPlaying(false); selectEpisode(api.episode - 1); });
ui.nextEp.addEventListener('click', () => { setPlaying(false); selectEpisode(api.episode + 1); });
ui.play.addEventListener('click', () => setPlaying(!api.playing));
ui.speed.addEventListener('change', () => setSpeed(ui.speed.value));
ui.scrub.addEventListener('input', () => {
  setPlaying(false);
  frameFloat = Number(ui.scrub.value);
  applyFrame(frameFloat);
});
ui.follow.addEventListener('change', () => setFollow(ui.follow.checked));
ui.trail.addEventListener('change', () => { trail.visible = ui.trail.checked; dirty = true; });
window.addEventListener('keydown', (e) => {
  if (e.target instanceof HTMLInputElement && e.target.type !== 'range' && e.target.type !== 'checkbox') return;
  if (e.target instanceof HTMLSelectElement) return;
  if (!ep) return;
  const stepBy = e.shiftKey ? 10 : 1;
  if (e.key === ' ') { setPlaying(!api.playing); e.preventDefault(); }
  else if (e.key === 'ArrowRight') { setPlaying(false); applyFrame(api.frame + stepBy); frameFloat = api.frame; e.preventDefault(); }
  else if (e.key === 'ArrowLeft') { setPlaying(false); applyFrame(api.frame - stepBy); frameFloat = api.frame; e.preventDefault(); }
  else if (e.key === '[') { setPlaying(false); selectEpisode(api.episode - 1); }
  else if (e.key === ']') { setPlaying(false); selectEpisode(api.episode + 1); }
  else if (e.key === 'f') setFollow(!api.follow);
});

Object.assign(api, {
  seek,
  play: () => setPlaying(true),
  pause: () => setPlaying(false),
  setFollow,
  setSpeed,
  selectEpisode: (i) => { selectEpisode(i); render(); },
  loadUrl,
  renderNow: render,
  // World position of a body's frame origin as drawn, in recording (z-up) coordinates.
  bodyWorld(name) {
    if (!humanoid || !humanoid.names.has(name)) return null;
    world.updateMatrixWorld(true);
    return threeToRec(humanoid.bodies[humanoid.names.get(name)].getWorldPosition(new THREE.Vector3()));
  },
  // The chair frame's origin as drawn (recording coordinates), null when no chair is drawn.
  chairWorld() {
    if (!chair.visible || chair.children.length === 0) return null;
    world.updateMatrixWorld(true);
    return threeToRec(chair.getWorldPosition(new THREE.Vector3()));
  },
  // Centre of the chair box with this role (first match) as drawn, recording coordinates.
  chairBoxWorld(role) {
    if (!chair.visible) return null;
    const m = chair.children.find((c) => c.isMesh && c.name === role);
    if (!m) return null;
    world.updateMatrixWorld(true);
    return threeToRec(m.getWorldPosition(new THREE.Vector3()));
  },
  walkTargetWorld() {
    if (!walkMarker.visible) return null;
    world.updateMatrixWorld(true);
    return threeToRec(walkMarker.getWorldPosition(new THREE.Vector3()));
  },
  // Page pixel [x, y] (CSS pixels) of a recording-space point; null when behind the camera.
  project(x, y, z) {
    if (!renderer) return null;
    camera.updateMatrixWorld(true);
    const v = recToThree(x, y, z).project(camera);
    if (v.z > 1 || v.z < -1) return null;
    const r = renderer.domElement.getBoundingClientRect();
    return [r.left + (v.x + 1) / 2 * r.width, r.top + (1 - v.y) / 2 * r.height];
  },
  hudText: () => ui.hud.innerText,
  colors: COLORS,
  three: { scene, camera, renderer, controls, world, ground },
});

// ?file=URL (relative to this page)
const fileParam = new URLSearchParams(window.location.search).get('file');
if (fileParam && renderer) loadUrl(fileParam);
