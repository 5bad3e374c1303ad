//! A bounds-checked reader over the file's bytes: every read names what it expected and fails
//! with the file, the grid and the offset instead of reading past the end.

use crate::export::ExportError;
use std::path::Path;

pub(super) struct Cursor<'a> {
    pub(super) path: &'a Path,
    pub(super) bytes: &'a [u8],
    pub(super) pos: usize,
    pub(super) version: u32,
    pub(super) grid: String,
}

impl<'a> Cursor<'a> {
    pub(super) fn corrupt(&self, problem: impl Into<String>) -> ExportError {
        let problem = problem.into();
        let problem = if self.grid.is_empty() { problem } else { format!("grid {:?}: {problem}", self.grid) };
        ExportError::Corrupt { path: self.path.to_path_buf(), problem, offset: self.pos as u64 }
    }
    pub(super) fn remaining(&self) -> usize {
        self.bytes.len().saturating_sub(self.pos)
    }
    pub(super) fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], ExportError> {
        if n > self.remaining() {
            return Err(self
                .corrupt(format!("{what} needs {n} bytes but only {} are left (truncated file?)", self.remaining())));
        }
        let s = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    pub(super) fn arr<const N: usize>(&mut self, what: &str) -> Result<[u8; N], ExportError> {
        let s = self.take(N, what)?;
        let mut a = [0u8; N];
        a.copy_from_slice(s);
        Ok(a)
    }
    pub(super) fn u8(&mut self, what: &str) -> Result<u8, ExportError> {
        Ok(self.arr::<1>(what)?[0])
    }
    pub(super) fn u32(&mut self, what: &str) -> Result<u32, ExportError> {
        Ok(u32::from_le_bytes(self.arr(what)?))
    }
    pub(super) fn i32(&mut self, what: &str) -> Result<i32, ExportError> {
        Ok(i32::from_le_bytes(self.arr(what)?))
    }
    pub(super) fn i64(&mut self, what: &str) -> Result<i64, ExportError> {
        Ok(i64::from_le_bytes(self.arr(what)?))
    }
    pub(super) fn f32(&mut self, what: &str) -> Result<f32, ExportError> {
        Ok(f32::from_le_bytes(self.arr(what)?))
    }
    pub(super) fn f64(&mut self, what: &str) -> Result<f64, ExportError> {
        Ok(f64::from_le_bytes(self.arr(what)?))
    }
    pub(super) fn vec3d(&mut self, what: &str) -> Result<[f64; 3], ExportError> {
        Ok([self.f64(what)?, self.f64(what)?, self.f64(what)?])
    }
    pub(super) fn string(&mut self, what: &str) -> Result<String, ExportError> {
        let n = self.u32(what)? as usize;
        let s = self.take(n, what)?;
        Ok(String::from_utf8_lossy(s).into_owned())
    }
    /// A count of items of at least `min_bytes` each, checked against the bytes left.
    pub(super) fn count(&mut self, min_bytes: usize, what: &str) -> Result<usize, ExportError> {
        let n = self.u32(what)? as usize;
        if n.saturating_mul(min_bytes.max(1)) > self.remaining() {
            return Err(self.corrupt(format!("{what} is {n}, more than the {} bytes left can hold", self.remaining())));
        }
        Ok(n)
    }
    pub(super) fn mask(&mut self, words: usize, what: &str) -> Result<Vec<u64>, ExportError> {
        let s = self.take(words * 8, what)?;
        Ok(s.chunks_exact(8).map(|c| u64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]])).collect())
    }
}

pub(super) fn checked_pos(cur: &Cursor, pos: usize) -> Result<usize, ExportError> {
    if pos > cur.bytes.len() {
        return Err(
            cur.corrupt(format!("an offset ({pos}) points past the end of the file ({} bytes)", cur.bytes.len()))
        );
    }
    Ok(pos)
}
