//! Value blocks as OpenVDB compresses them: uncompressed, zip (zlib, through flate2) or blosc
//! (byte shuffle with the LZ4 or zlib codec; our own decoder), each of a known expected size.

use super::cursor::Cursor;
use crate::export::vdb::{COMPRESS_BLOSC, COMPRESS_ZIP};
use crate::export::ExportError;
use std::io::Read;

/// OpenVDB's `readData`: `expected` bytes, raw or in a zip/blosc chunk (`i64` size first; a
/// negative size means raw bytes follow).
pub(super) fn read_data(cur: &mut Cursor, compression: u32, expected: usize) -> Result<Vec<u8>, ExportError> {
    if compression & (COMPRESS_BLOSC | COMPRESS_ZIP) == 0 {
        return Ok(cur.take(expected, "a value block")?.to_vec());
    }
    let size_at = cur.pos;
    let n = cur.i64("a compressed block's size")?;
    if n <= 0 {
        let raw = n.unsigned_abs();
        if raw != expected as u64 {
            cur.pos = size_at;
            return Err(cur.corrupt(format!("an uncompressed block holds {raw} bytes, expected {expected}")));
        }
        return Ok(cur.take(expected, "a value block")?.to_vec());
    }
    let n = n as u64;
    if n > cur.remaining() as u64 {
        let left = cur.remaining();
        cur.pos = size_at;
        return Err(cur.corrupt(format!("a compressed block of {n} bytes is longer than the {left} bytes left")));
    }
    let start = cur.pos;
    let src = cur.take(n as usize, "a compressed block")?;
    let result = if compression & COMPRESS_BLOSC != 0 {
        blosc_decompress(src, expected)
    } else {
        zlib_decompress(src, expected)
    };
    result.map_err(|problem| {
        cur.pos = start;
        cur.corrupt(problem)
    })
}

fn zlib_decompress(src: &[u8], expected: usize) -> Result<Vec<u8>, String> {
    let mut out = vec![0u8; expected];
    let mut dec = flate2::read::ZlibDecoder::new(src);
    dec.read_exact(&mut out).map_err(|e| format!("zip block does not inflate to {expected} bytes: {e}"))?;
    let mut extra = [0u8; 1];
    match dec.read(&mut extra) {
        Ok(0) => Ok(out),
        Ok(_) => Err(format!("zip block inflates to more than {expected} bytes")),
        Err(e) => Err(format!("zip block: {e}")),
    }
}

/// Decompresses one blosc (version 1 format) chunk: 16-byte header (version, codec version,
/// flags, type size, u32 uncompressed size, u32 block size, u32 compressed size), then either
/// the raw bytes (flag 0x02) or a table of block offsets and, per block, one or `typesize`
/// (split) streams each prefixed by its i32 compressed size; byte-shuffled when flag 0x01.
fn blosc_decompress(src: &[u8], expected: usize) -> Result<Vec<u8>, String> {
    if src.len() < 16 {
        return Err(format!("blosc chunk of {} bytes is shorter than its 16-byte header", src.len()));
    }
    let rd = |at: usize| u32::from_le_bytes([src[at], src[at + 1], src[at + 2], src[at + 3]]) as usize;
    let flags = src[2];
    let typesize = src[3] as usize;
    let nbytes = rd(4);
    let blocksize = rd(8);
    let cbytes = rd(12);
    if nbytes != expected {
        return Err(format!("blosc chunk holds {nbytes} bytes, expected {expected}"));
    }
    if cbytes > src.len() {
        return Err(format!("blosc chunk says {cbytes} bytes, only {} are there", src.len()));
    }
    if flags & 0x02 != 0 {
        // memcpyed: stored raw after the header.
        return src.get(16..16 + nbytes).map(|s| s.to_vec()).ok_or_else(|| "raw blosc chunk is truncated".to_string());
    }
    if nbytes == 0 {
        return Ok(Vec::new());
    }
    if blocksize == 0 || typesize == 0 {
        return Err(format!("blosc chunk has block size {blocksize} and type size {typesize}"));
    }
    let codec = flags >> 5;
    if codec != 1 && codec != 3 {
        let name = match codec {
            0 => "blosclz",
            2 => "snappy",
            4 => "zstd",
            _ => "unknown",
        };
        return Err(format!("blosc codec {name} is not supported (OpenVDB writes lz4; lz4 and zlib are supported)"));
    }
    if flags & 0x04 != 0 {
        return Err("blosc bitshuffle is not supported (OpenVDB writes byte shuffle)".into());
    }
    let shuffled = flags & 0x01 != 0 && typesize > 1;
    let dont_split = flags & 0x10 != 0;
    let nblocks = nbytes.div_ceil(blocksize);
    let leftover = nbytes % blocksize;
    if 16 + nblocks * 4 > src.len() {
        return Err("blosc block table is truncated".into());
    }
    let mut out = vec![0u8; nbytes];
    // No block is larger than the buffer (a larger declared block size means one leftover block).
    let mut tmp = vec![0u8; blocksize.min(nbytes)];
    for b in 0..nblocks {
        let is_leftover = b == nblocks - 1 && leftover > 0;
        let bsize = if is_leftover { leftover } else { blocksize };
        let mut at = rd(16 + 4 * b);
        let nsplits =
            if !dont_split && typesize <= 16 && blocksize / typesize >= 128 && !is_leftover { typesize } else { 1 };
        let neblock = bsize / nsplits;
        let block = &mut tmp[..bsize];
        for s in 0..nsplits {
            if at + 4 > src.len() {
                return Err("blosc stream header is out of bounds".into());
            }
            let csize = i32::from_le_bytes([src[at], src[at + 1], src[at + 2], src[at + 3]]);
            at += 4;
            if csize < 0 || at + csize as usize > src.len() {
                return Err(format!("blosc stream size {csize} is out of bounds"));
            }
            let stream = &src[at..at + csize as usize];
            at += csize as usize;
            let dst = &mut block[s * neblock..(s + 1) * neblock];
            if csize as usize == neblock {
                dst.copy_from_slice(stream);
            } else if codec == 1 {
                let got =
                    lz4_flex::block::decompress_into(stream, dst).map_err(|e| format!("blosc lz4 stream: {e}"))?;
                if got != neblock {
                    return Err(format!("blosc lz4 stream gave {got} bytes, expected {neblock}"));
                }
            } else {
                let got = zlib_decompress(stream, neblock)?;
                dst.copy_from_slice(&got);
            }
        }
        let dst = &mut out[b * blocksize..b * blocksize + bsize];
        if shuffled {
            // Byte b of element i was stored at b·n + i.
            let n = bsize / typesize;
            for i in 0..n {
                for byte in 0..typesize {
                    dst[i * typesize + byte] = block[byte * n + i];
                }
            }
            let tail = n * typesize;
            dst[tail..].copy_from_slice(&block[tail..]);
        } else {
            dst.copy_from_slice(block);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A blosc chunk as c-blosc lays it out, built by hand: one block, LZ4, byte shuffle.
    fn blosc_chunk(data: &[u8], typesize: usize, split: bool, flags_extra: u8) -> Vec<u8> {
        let n = data.len() / typesize;
        let mut shuffled = vec![0u8; data.len()];
        for i in 0..n {
            for b in 0..typesize {
                shuffled[b * n + i] = data[i * typesize + b];
            }
        }
        let mut out = vec![2u8, 1, 0x01 | (1 << 5) | flags_extra | if split { 0 } else { 0x10 }, typesize as u8];
        out.extend_from_slice(&(data.len() as u32).to_le_bytes());
        out.extend_from_slice(&(data.len() as u32).to_le_bytes()); // one block
        out.extend_from_slice(&0u32.to_le_bytes()); // cbytes, patched below
        out.extend_from_slice(&20u32.to_le_bytes()); // block 0 starts after the table
        let streams = if split { typesize } else { 1 };
        let len = data.len() / streams;
        for s in 0..streams {
            let c = lz4_flex::block::compress(&shuffled[s * len..(s + 1) * len]);
            out.extend_from_slice(&(c.len() as i32).to_le_bytes());
            out.extend_from_slice(&c);
        }
        let total = out.len() as u32;
        out[12..16].copy_from_slice(&total.to_le_bytes());
        out
    }

    fn floats() -> Vec<u8> {
        (0..512).flat_map(|i| ((i / 7) as f32 * 0.25).to_le_bytes()).collect()
    }

    #[test]
    fn blosc_lz4_shuffled_split_and_unsplit() {
        let data = floats();
        for split in [false, true] {
            let chunk = blosc_chunk(&data, 4, split, 0);
            assert_eq!(blosc_decompress(&chunk, data.len()).unwrap(), data, "split {split}");
        }
    }

    #[test]
    fn blosc_memcpyed_and_errors() {
        let data = floats();
        let mut raw = vec![2u8, 1, 0x02 | 0x01, 4];
        raw.extend_from_slice(&(data.len() as u32).to_le_bytes());
        raw.extend_from_slice(&(data.len() as u32).to_le_bytes());
        raw.extend_from_slice(&((data.len() + 16) as u32).to_le_bytes());
        raw.extend_from_slice(&data);
        assert_eq!(blosc_decompress(&raw, data.len()).unwrap(), data);
        // Wrong size, truncation, bitshuffle, other codecs: errors.
        assert!(blosc_decompress(&raw, 16).unwrap_err().contains("expected 16"));
        // A huge declared block size allocates nothing big: here it makes the data one
        // unsplit leftover block, which does not decode.
        let mut big = blosc_chunk(&data, 4, true, 0);
        big[8..12].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(blosc_decompress(&big, data.len()).is_err());
        let chunk = blosc_chunk(&data, 4, true, 0);
        for cut in 0..chunk.len() {
            assert!(blosc_decompress(&chunk[..cut], data.len()).is_err());
        }
        assert!(blosc_decompress(&blosc_chunk(&data, 4, true, 0x04), data.len()).unwrap_err().contains("bitshuffle"));
        let mut zstd = blosc_chunk(&data, 4, true, 0);
        zstd[2] = (zstd[2] & 0x1f) | (4 << 5);
        assert!(blosc_decompress(&zstd, data.len()).unwrap_err().contains("zstd"));
    }
}
