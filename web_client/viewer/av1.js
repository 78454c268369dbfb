// AV1 helpers: split a temporal unit of low-overhead OBUs (AV1 spec section 5.3) and build the
// WebCodecs codec string from its sequence header OBU (section 5.5; the string's form is the
// AV1 ISOBMFF binding's "av01.P.LLT.DD", section "Codecs Parameter String"). Pure (no DOM), so
// node can unit-test it.

export const OBU_SEQUENCE_HEADER = 1;
export const OBU_TEMPORAL_DELIMITER = 2;
export const OBU_FRAME_HEADER = 3;
export const OBU_FRAME = 6;

// Reads bits most significant first (the spec's f(n)).
class BitReader {
  constructor(bytes) {
    this.bytes = bytes;
    this.pos = 0;
  }

  bit() {
    const byte = this.pos >> 3;
    if (byte >= this.bytes.length) throw new Error('av1: sequence header ends early');
    const b = (this.bytes[byte] >> (7 - (this.pos & 7))) & 1;
    this.pos++;
    return b;
  }

  bits(n) {
    let v = 0;
    for (let i = 0; i < n; i++) v = v * 2 + this.bit();
    return v;
  }

  // uvlc() (section 4.10.3).
  uvlc() {
    let zeros = 0;
    while (!this.bit()) {
      zeros++;
      if (zeros >= 32) return 2 ** 32 - 1;
    }
    return this.bits(zeros) + 2 ** zeros - 1;
  }
}

// leb128() (section 4.10.5) at `bytes[at]`: { value, size } in bytes.
function leb128(bytes, at) {
  let value = 0;
  for (let i = 0; i < 8; i++) {
    if (at + i >= bytes.length) throw new Error('av1: OBU size runs past the temporal unit');
    const b = bytes[at + i];
    value += (b & 0x7f) * 2 ** (7 * i);
    if (!(b & 0x80)) return { value, size: i + 1 };
  }
  throw new Error('av1: OBU size longer than 8 bytes');
}

// The OBUs of a temporal unit: [{ type, payload }]. Every OBU must carry its size
// (obu_has_size_field), as the low-overhead format requires. Throws on a malformed unit.
export function splitObus(bytes) {
  const obus = [];
  let at = 0;
  while (at < bytes.length) {
    const header = bytes[at];
    if (header & 0x80) throw new Error('av1: OBU forbidden bit set');
    const type = (header >> 3) & 0x0f;
    const extension = (header >> 2) & 1;
    if (!((header >> 1) & 1)) throw new Error('av1: OBU without a size field');
    at += 1 + extension;
    const { value, size } = leb128(bytes, at);
    at += size;
    if (at + value > bytes.length) throw new Error('av1: OBU runs past the temporal unit');
    obus.push({ type, payload: bytes.subarray(at, at + value) });
    at += value;
  }
  return obus;
}

// seq_profile, and operating point 0's seq_level_idx and seq_tier, from a sequence header OBU's
// payload (section 5.5.1; the fields before them are read only to be skipped).
export function parseSequenceHeader(payload) {
  const r = new BitReader(payload);
  const profile = r.bits(3);
  r.bit(); // still_picture
  const reduced = r.bit();
  if (reduced) return { profile, level: r.bits(5), tier: 0 };
  let decoderModelInfo = 0;
  if (r.bit()) {
    // timing_info()
    r.bits(32); // num_units_in_display_tick
    r.bits(32); // time_scale
    if (r.bit()) r.uvlc(); // equal_picture_interval: num_ticks_per_picture_minus_1
    decoderModelInfo = r.bit();
    if (decoderModelInfo) r.bits(5 + 32 + 5 + 5); // decoder_model_info()
  }
  r.bit(); // initial_display_delay_present_flag
  r.bits(5); // operating_points_cnt_minus_1
  r.bits(12); // operating_point_idc[0]
  const level = r.bits(5);
  const tier = level > 7 ? r.bit() : 0;
  return { profile, level, tier };
}

const dec2 = (v) => String(v).padStart(2, '0');

// "av01.P.LLT.08": profile, operating point 0's level (two digits) and tier (M or H), 8 bits (the
// server's streams are 8-bit 4:2:0, BT.709).
export function codecStringFromSequenceHeader(payload) {
  const { profile, level, tier } = parseSequenceHeader(payload);
  return `av01.${profile}.${dec2(level)}${tier ? 'H' : 'M'}.08`;
}

// What the decoder needs to know about one temporal unit: whether it carries a sequence header
// (every key frame of the server's streams does) and the codec string from it.
export function inspectTemporalUnit(bytes) {
  let sequenceHeader = null;
  let hasFrame = false;
  for (const obu of splitObus(bytes)) {
    if (obu.type === OBU_SEQUENCE_HEADER && !sequenceHeader) sequenceHeader = obu.payload;
    else if (obu.type === OBU_FRAME || obu.type === OBU_FRAME_HEADER) hasFrame = true;
  }
  return { sequenceHeader, hasFrame, codec: sequenceHeader ? codecStringFromSequenceHeader(sequenceHeader) : null };
}
