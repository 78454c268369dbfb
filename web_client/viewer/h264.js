// H.264 Annex B helpers: split an access unit into NAL units, find the SPS, build the WebCodecs
// codec string. Pure (no DOM), so node can unit-test it.

export const NAL_SLICE = 1;
export const NAL_IDR = 5;
export const NAL_SPS = 7;
export const NAL_PPS = 8;

// NAL units of an Annex B byte stream (start codes 00 00 01 or 00 00 00 01), as subarrays
// without the start code. Bytes before the first start code are ignored.
export function splitAnnexB(bytes) {
  const nals = [];
  const n = bytes.length;
  let start = -1;
  let i = 0;
  while (i + 2 < n) {
    if (bytes[i] === 0 && bytes[i + 1] === 0 && bytes[i + 2] === 1) {
      if (start >= 0) {
        // A 4-byte start code leaves one zero at the end of the previous NAL: trim trailing zeros.
        let end = i;
        while (end > start && bytes[end - 1] === 0) end--;
        nals.push(bytes.subarray(start, end));
      }
      start = i + 3;
      i += 3;
    } else {
      i++;
    }
  }
  if (start >= 0 && start < n) nals.push(bytes.subarray(start, n));
  return nals.filter((nal) => nal.length > 0);
}

export const nalType = (nal) => nal[0] & 0x1f;

// Removes emulation-prevention bytes (00 00 03 -> 00 00) from a NAL unit's payload.
export function unescapeRbsp(nal) {
  const out = new Uint8Array(nal.length);
  let o = 0;
  let zeros = 0;
  for (let i = 0; i < nal.length; i++) {
    const b = nal[i];
    if (zeros >= 2 && b === 3) {
      zeros = 0;
      continue;
    }
    zeros = b === 0 ? zeros + 1 : 0;
    out[o++] = b;
  }
  return out.subarray(0, o);
}

// profile_idc, constraint_set flags byte and level_idc: the first three bytes after the SPS NAL
// header (H.264 7.3.2.1.1).
export function parseSpsHeader(sps) {
  const rbsp = unescapeRbsp(sps);
  if (rbsp.length < 4 || nalType(rbsp) !== NAL_SPS) throw new Error('not an SPS NAL unit');
  return { profileIdc: rbsp[1], constraintFlags: rbsp[2], levelIdc: rbsp[3] };
}

const hex2 = (v) => v.toString(16).toUpperCase().padStart(2, '0');

// "avc1.PPCCLL" (RFC 6381) from the SPS.
export function codecStringFromSps(sps) {
  const { profileIdc, constraintFlags, levelIdc } = parseSpsHeader(sps);
  return `avc1.${hex2(profileIdc)}${hex2(constraintFlags)}${hex2(levelIdc)}`;
}

// What the decoder needs to know about one access unit.
export function inspectAccessUnit(bytes) {
  let sps = null;
  let hasIdr = false;
  let hasSlice = false;
  for (const nal of splitAnnexB(bytes)) {
    const t = nalType(nal);
    if (t === NAL_SPS && !sps) sps = nal;
    else if (t === NAL_IDR) hasIdr = true;
    else if (t === NAL_SLICE) hasSlice = true;
  }
  return { sps, hasIdr, hasSlice, codec: sps ? codecStringFromSps(sps) : null };
}
