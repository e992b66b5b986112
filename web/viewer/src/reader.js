// Reader (and, for tests, writer) of Perch recording files (docs/recording.md):
//   24-byte header: "PERCHREC", uint32 LE format (= 1), uint64 LE payload length,
//   uint32 LE CRC-32 (zlib / IEEE 802.3) of the payload; then one perch.proto.Recording.
// The message schema is the .proto text itself (common/proto/recording.proto), passed in by the
// caller: the browser bundle embeds it at build time (esbuild text loader), Node tests read it.
import protobuf from 'protobufjs';

export const MAGIC = 'PERCHREC';
export const FORMAT = 1;
export const HEADER_BYTES = 24;

const CRC_TABLE = (() => {
  const t = new Uint32Array(256);
  for (let n = 0; n < 256; n++) {
    let c = n;
    for (let k = 0; k < 8; k++) c = c & 1 ? 0xedb88320 ^ (c >>> 1) : c >>> 1;
    t[n] = c >>> 0;
  }
  return t;
})();

// CRC-32 as zlib's crc32(0, data, len).
export function crc32(bytes) {
  let c = 0xffffffff;
  for (let i = 0; i < bytes.length; i++) c = CRC_TABLE[(c ^ bytes[i]) & 0xff] ^ (c >>> 8);
  return (c ^ 0xffffffff) >>> 0;
}

export class RecordingError extends Error {
  constructor(message) {
    super(message);
    this.name = 'RecordingError';
  }
}

function toBytes(data) {
  if (data instanceof Uint8Array) return data;
  if (data instanceof ArrayBuffer) return new Uint8Array(data);
  if (ArrayBuffer.isView(data)) return new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
  throw new TypeError('recording data must be an ArrayBuffer or a Uint8Array');
}

const SUBTASK_NAMES = { 0: 'left turn', 1: 'right turn', 2: 'sit', 3: 'walk' };
export function subtaskName(id) {
  return SUBTASK_NAMES[id] ?? null;  // -1 (none) and unknown ids: null
}

// createCodec(protoText) -> { Recording, readRecording(data, name), encodeRecordingFile(obj) }
export function createCodec(protoText) {
  const root = protobuf.parse(protoText, { keepCase: true }).root;
  const Recording = root.lookupType('perch.proto.Recording');

  // Reads and checks a whole recording file; throws RecordingError naming the file and the problem.
  function readRecording(data, name = 'recording') {
    const bytes = toBytes(data);
    const fail = (what) => { throw new RecordingError(`${name}: ${what}`); };
    if (bytes.length < HEADER_BYTES) {
      const head = String.fromCharCode(...bytes.subarray(0, Math.min(8, bytes.length)));
      if (head !== MAGIC.slice(0, head.length) || bytes.length === 0) fail('not a recording (no PERCHREC magic)');
      fail(`truncated or corrupt: ${bytes.length} bytes, shorter than the ${HEADER_BYTES}-byte header`);
    }
    const magic = String.fromCharCode(...bytes.subarray(0, 8));
    if (magic !== MAGIC) fail('not a recording (no PERCHREC magic)');
    const view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
    const format = view.getUint32(8, true);
    if (format !== FORMAT) fail(`format ${format}, this build reads ${FORMAT}`);
    const length = view.getBigUint64(12, true);
    const actual = BigInt(bytes.length - HEADER_BYTES);
    if (length !== actual) {
      fail(`truncated or corrupt: the header says ${length} payload bytes, the file has ${actual}`);
    }
    const payload = bytes.subarray(HEADER_BYTES);
    const want = view.getUint32(20, true);
    const got = crc32(payload);
    if (want !== got) {
      fail(`corrupt: payload CRC-32 ${hex(got)} differs from the header's ${hex(want)}`);
    }
    let msg;
    try {
      msg = Recording.decode(payload);
    } catch (e) {
      fail(`corrupt: the payload does not parse as perch.proto.Recording (${e.message})`);
    }
    const rec = Recording.toObject(msg, { longs: String, defaults: true, arrays: true, objects: true });
    if (rec.format_version !== format) {
      fail(`format_version ${rec.format_version} in the message differs from the file's format ${format}`);
    }
    validate(rec, fail);
    return rec;  // uint64 fields (seed) as decimal strings: exact
  }

  // Frames a Recording (plain object, field names as in the .proto) as a file (Uint8Array).
  function encodeRecordingFile(obj, { format = FORMAT } = {}) {
    const msg = Recording.fromObject(obj);
    const err = Recording.verify(msg);
    if (err) throw new Error(`invalid Recording: ${err}`);
    const payload = Recording.encode(msg).finish();
    const out = new Uint8Array(HEADER_BYTES + payload.length);
    for (let i = 0; i < 8; i++) out[i] = MAGIC.charCodeAt(i);
    const view = new DataView(out.buffer);
    view.setUint32(8, format, true);
    view.setBigUint64(12, BigInt(payload.length), true);
    view.setUint32(20, crc32(payload), true);
    out.set(payload, HEADER_BYTES);
    return out;
  }

  return { Recording, readRecording, encodeRecordingFile };
}

function hex(v) {
  return '0x' + v.toString(16).padStart(8, '0');
}

// Shape checks a viewer relies on (array sizes per frame).
function validate(rec, fail) {
  const nb = rec.bodies.length;
  if (nb === 0) fail('corrupt: the recording has no bodies');
  rec.episodes.forEach((ep, e) => {
    const c = ep.chair;
    if (c && (c.mesh_vertices.length > 0 || c.mesh_triangles.length > 0)) {
      const where = `episode ${ep.index} (#${e}) chair ${c.name}`;
      const nv = c.mesh_vertices.length / 3;
      if (!Number.isInteger(nv)) fail(`corrupt: ${where} has ${c.mesh_vertices.length} mesh_vertices values, not a multiple of 3`);
      if (c.mesh_triangles.length % 3 !== 0) fail(`corrupt: ${where} has ${c.mesh_triangles.length} mesh_triangles values, not a multiple of 3`);
      for (const i of c.mesh_triangles) {
        if (i >= nv) fail(`corrupt: ${where} names mesh vertex ${i} of ${nv}`);
      }
    }
    ep.frames.forEach((fr, f) => {
      const where = `episode ${ep.index} (#${e}) frame ${f}`;
      if (fr.body_pos.length !== 3 * nb) fail(`corrupt: ${where} has ${fr.body_pos.length} body_pos values, expected ${3 * nb}`);
      if (fr.body_quat.length !== 4 * nb) fail(`corrupt: ${where} has ${fr.body_quat.length} body_quat values, expected ${4 * nb}`);
      if (fr.chair_pos.length !== 0 && fr.chair_pos.length !== 3) fail(`corrupt: ${where} has ${fr.chair_pos.length} chair_pos values`);
      if (fr.chair_pos.length === 3 && fr.chair_quat.length !== 4) fail(`corrupt: ${where} has ${fr.chair_quat.length} chair_quat values`);
    });
  });
}
