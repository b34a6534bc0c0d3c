// The zstd frame checks the C++ decoder makes before it decompresses (protocol/src/mesh_codec.cc,
// DecompressPayload): one frame, its content size declared and within a limit, nothing after it.
// Pure; allocates nothing.

const kMagic = 0xfd2fb528;

/**
 * The declared content size of the zstd frame at the start of `data`, and the frame's size in
 * bytes, or an error text. Reads only headers (frame header, then each block header).
 * @param {Uint8Array} data
 * @returns {{contentSize: number, frameSize: number, error: string}}
 */
export function inspectZstdFrame(data) {
  const result = { contentSize: -1, frameSize: 0, error: '' };
  if (data.length < 6 || readU32(data, 0) !== kMagic) {
    result.error = 'payload is not a zstd frame';
    return result;
  }
  // Frame header descriptor: content-size flag, single segment, checksum, dictionary id size.
  const fhd = data[4];
  const fcsFlag = fhd >> 6;
  const singleSegment = (fhd >> 5) & 1;
  const checksum = (fhd >> 2) & 1;
  const dictIdBytes = [0, 1, 2, 4][fhd & 3];
  const fcsBytes = fcsFlag === 0 ? singleSegment : 1 << fcsFlag;
  let p = 5 + (singleSegment ? 0 : 1) + dictIdBytes;
  if (p + fcsBytes > data.length) {
    result.error = 'payload is not a zstd frame';
    return result;
  }
  if (fcsBytes === 0) {
    result.error = 'zstd frame does not declare its content size';
    return result;
  }
  let size = 0;
  for (let i = fcsBytes - 1; i >= 0; i--) size = size * 256 + data[p + i];
  if (fcsBytes === 2) size += 256;
  result.contentSize = size;
  p += fcsBytes;
  // Blocks: 3-byte headers (last flag, type, size); an RLE block holds one byte.
  for (;;) {
    if (p + 3 > data.length) {
      result.error = 'corrupt zstd frame: Src size is incorrect';
      return result;
    }
    const header = data[p] | (data[p + 1] << 8) | (data[p + 2] << 16);
    const last = header & 1;
    const type = (header >> 1) & 3;
    const blockSize = header >>> 3;
    if (type === 3) {
      result.error = 'corrupt zstd frame: Corrupted block detected';
      return result;
    }
    p += 3 + (type === 1 ? 1 : blockSize);
    if (p > data.length) {
      result.error = 'corrupt zstd frame: Src size is incorrect';
      return result;
    }
    if (last) break;
  }
  p += checksum ? 4 : 0;
  if (p > data.length) {
    result.error = 'corrupt zstd frame: Src size is incorrect';
    return result;
  }
  result.frameSize = p;
  return result;
}

/** @param {Uint8Array} d @param {number} p */
function readU32(d, p) {
  return (d[p] | (d[p + 1] << 8) | (d[p + 2] << 16) | (d[p + 3] << 24)) >>> 0;
}
