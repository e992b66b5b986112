// Node unit test of the recording reader (src/reader.js): round trip of a synthetic recording with
// known poses, and the refusals of docs/recording.md (truncated, CRC, magic, format, parse).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import zlib from 'node:zlib';
import { createCodec, crc32, subtaskName, RecordingError, HEADER_BYTES } from '../src/reader.js';
import { PROTO_TEXT, makeSyntheticRecording, SYNTH } from './synth.mjs';

const codec = createCodec(PROTO_TEXT);
const NAME = 'synthetic.rec';
const original = makeSyntheticRecording();
const file = codec.encodeRecordingFile(original);

// Builds a framed file around an arbitrary payload with a correct length and CRC.
function frame(payload, format = 1) {
  const out = new Uint8Array(HEADER_BYTES + payload.length);
  out.set(new TextEncoder().encode('PERCHREC'));
  const v = new DataView(out.buffer);
  v.setUint32(8, format, true);
  v.setBigUint64(12, BigInt(payload.length), true);
  v.setUint32(20, crc32(payload), true);
  out.set(payload, HEADER_BYTES);
  return out;
}

function refuses(bytes, pattern) {
  assert.throws(() => codec.readRecording(bytes, NAME), (e) => {
    assert.ok(e instanceof RecordingError, `a RecordingError, got ${e}`);
    assert.ok(e.message.startsWith(`${NAME}: `), `names the file: ${e.message}`);
    assert.match(e.message, pattern);
    return true;
  });
}

const close = (a, b, what) => {
  assert.equal(a.length, b.length, `${what}: length`);
  a.forEach((v, i) => assert.ok(Math.abs(v - b[i]) < 1e-6, `${what}[${i}]: ${v} vs ${b[i]}`));
};

test('crc32 is zlib\'s CRC-32', () => {
  assert.equal(crc32(new TextEncoder().encode('123456789')), 0xcbf43926);
  assert.equal(crc32(new Uint8Array(0)), 0);
  if (typeof zlib.crc32 === 'function') {
    const data = new Uint8Array(4099).map((_, i) => (i * 131 + 7) & 0xff);
    assert.equal(crc32(data), zlib.crc32(data));
  }
});

test('the header is the documented layout', () => {
  assert.equal(new TextDecoder().decode(file.subarray(0, 8)), 'PERCHREC');
  const v = new DataView(file.buffer, file.byteOffset);
  assert.equal(v.getUint32(8, true), 1);
  assert.equal(v.getBigUint64(12, true), BigInt(file.length - 24));
  assert.equal(v.getUint32(20, true), crc32(file.subarray(24)));
});

test('round trip keeps the header, the shapes and the poses', () => {
  const rec = codec.readRecording(file, NAME);
  assert.equal(rec.format_version, 1);
  assert.equal(rec.task, 'sit');
  assert.equal(rec.seed, '7');
  assert.equal(rec.episodes[1].seed, '101');
  assert.equal(rec.episodes[2].seed, '12345678901234567891', 'uint64 seeds are exact');
  assert.ok(Math.abs(rec.control_dt - 1 / 60) < 1e-7);
  assert.deepEqual(rec.bodies.map((b) => b.name), original.bodies.map((b) => b.name));
  assert.equal(rec.bodies.length, 13);
  assert.equal(rec.bodies[0].parent, -1);
  assert.equal(rec.bodies.find((b) => b.name === 'torso').geoms[1].type, 'sphere');
  close(rec.bodies[2].geoms[0].from, original.bodies[2].geoms[0].from, 'pelvis capsule from');
  assert.equal(rec.episodes.length, 3);
  assert.deepEqual(rec.episodes.map((e) => e.outcome), ['success', 'fell', 'time_limit']);
  const e0 = rec.episodes[0];
  assert.equal(e0.frames.length, SYNTH.frames);
  assert.deepEqual(e0.chair.boxes.map((b) => b.role), original.episodes[0].chair.boxes.map((b) => b.role));
  assert.equal(rec.episodes[2].chair, null, 'no chair in episode 2');
  const pelvis = rec.bodies.findIndex((b) => b.name === 'pelvis');
  for (const k of [0, 45, SYNTH.frames - 1]) {
    const f = e0.frames[k], g = original.episodes[0].frames[k];
    close(f.body_pos, g.body_pos, `frame ${k} body_pos`);
    close(f.body_quat, g.body_quat, `frame ${k} body_quat`);
    close(f.chair_pos, g.chair_pos, `frame ${k} chair_pos`);
    assert.equal(f.step, k);
    assert.equal(f.active_subtask, g.active_subtask);
  }
  // the known pelvis path: x0 -> x1 along x at y = 0
  const px = (k) => e0.frames[k].body_pos[3 * pelvis];
  assert.ok(Math.abs(px(SYNTH.frames - 1) - px(0) - (SYNTH.x1 - SYNTH.x0)) < 1e-5);
  assert.ok(Math.abs(e0.frames[10].reward_terms.alive - 0.5) < 1e-7);
  assert.equal(rec.episodes[1].frames[5].active_subtask, -1);
  assert.equal(subtaskName(-1), null);
  assert.equal(subtaskName(2), 'sit');
});

test('a truncated file is refused', () => {
  refuses(file.subarray(0, file.length - 100), /truncated or corrupt: the header says \d+ payload bytes, the file has \d+/);
  refuses(file.subarray(0, 16), /truncated or corrupt/);
  const longer = new Uint8Array(file.length + 3);
  longer.set(file);
  refuses(longer, /truncated or corrupt/);
});

test('a flipped payload byte fails the CRC', () => {
  const bad = file.slice();
  bad[HEADER_BYTES + Math.floor((bad.length - HEADER_BYTES) / 2)] ^= 0x40;
  refuses(bad, /corrupt: payload CRC-32 0x[0-9a-f]{8} differs from the header's 0x[0-9a-f]{8}/);
});

test('a wrong magic is not a recording', () => {
  const bad = file.slice();
  bad.set(new TextEncoder().encode('PERCHBNK'));
  refuses(bad, /not a recording/);
  refuses(new Uint8Array(0), /not a recording/);
  refuses(new TextEncoder().encode('<!doctype html><html>not found</html>'), /not a recording/);
});

test('format 2 is refused', () => {
  const bad = file.slice();
  new DataView(bad.buffer).setUint32(8, 2, true);
  refuses(bad, /format 2, this build reads 1/);
  refuses(codec.encodeRecordingFile(original, { format: 2 }), /format 2, this build reads 1/);
});

test('a payload that does not parse is refused', () => {
  refuses(frame(new Uint8Array([0x0a, 0xff, 0xff, 0xff, 0xff, 0x0f, 0x01])), /does not parse as perch\.proto\.Recording/);
});

test('format_version must match the file format', () => {
  refuses(codec.encodeRecordingFile({ ...original, format_version: 3 }), /format_version 3 in the message differs from the file's format 1/);
});

test('frames with the wrong number of body values are refused', () => {
  const bad = makeSyntheticRecording();
  bad.episodes[1].frames[3].body_pos = bad.episodes[1].frames[3].body_pos.slice(3);
  refuses(codec.encodeRecordingFile(bad), /episode 1 \(#1\) frame 3 has 36 body_pos values, expected 39/);
});

// A mesh chair travels as triangles (docs/recording.md): they round-trip, and a triangle that
// names a vertex the chair does not have is refused.
test('a mesh chair round-trips and a bad triangle index is refused', () => {
  const rec = makeSyntheticRecording();
  const verts = [0, 0, 0.4, 0.4, 0, 0.4, 0, 0.4, 0.4, 0.4, 0.4, 0.4];
  rec.episodes[0].chair = { name: 'mesh_chair', boxes: [], seat_target: [0.2, 0.2, 0.4],
                            mesh_vertices: verts, mesh_triangles: [0, 1, 2, 1, 3, 2], source: 'test' };
  const back = codec.readRecording(codec.encodeRecordingFile(rec), NAME);
  close(back.episodes[0].chair.mesh_vertices, verts, 'mesh_vertices');
  assert.deepEqual(back.episodes[0].chair.mesh_triangles, [0, 1, 2, 1, 3, 2]);
  assert.equal(back.episodes[0].chair.source, 'test');
  rec.episodes[0].chair.mesh_triangles = [0, 1, 4];
  refuses(codec.encodeRecordingFile(rec), /chair mesh_chair names mesh vertex 4 of 4/);
  rec.episodes[0].chair.mesh_triangles = [0, 1];
  refuses(codec.encodeRecordingFile(rec), /2 mesh_triangles values, not a multiple of 3/);
});
