//! NumPy `.npy` files (format version 1.0) written by hand: a shard is a handful of plain
//! arrays, and the format is a magic string, a Python-literal header and the raw
//! little-endian data, so no dependency is needed and `np.load(.., mmap_mode='r')` maps them.

use std::fmt::Write as _;

/// The element types the dataset uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dtype {
    U8,
    U32,
    F32,
}

impl Dtype {
    /// NumPy's type string (`descr`).
    #[must_use]
    pub fn descr(self) -> &'static str {
        match self {
            Dtype::U8 => "|u1",
            Dtype::U32 => "<u4",
            Dtype::F32 => "<f4",
        }
    }

    /// NumPy's name of the type (as `index.json` gives it).
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Dtype::U8 => "uint8",
            Dtype::U32 => "uint32",
            Dtype::F32 => "float32",
        }
    }

    #[must_use]
    pub fn size_bytes(self) -> usize {
        match self {
            Dtype::U8 => 1,
            Dtype::U32 | Dtype::F32 => 4,
        }
    }
}

/// The header of a C-order array of `dtype` and `shape`: magic, version 1.0, the length and
/// the dictionary, padded with spaces so that the data start on a 64-byte boundary (what
/// NumPy itself writes, so that memory maps are aligned).
#[must_use]
pub fn header(dtype: Dtype, shape: &[usize]) -> Vec<u8> {
    let mut dims = String::new();
    for d in shape {
        // Writing to a String cannot fail.
        let _ = write!(dims, "{d}, ");
    }
    // A 1-tuple needs its trailing comma; the others read fine with one too, but NumPy writes
    // `(a, b)`, so match it.
    let dims = if shape.len() == 1 {
        dims.trim_end().to_string()
    } else {
        dims.trim_end_matches(", ").to_string()
    };
    let mut dict = format!(
        "{{'descr': '{}', 'fortran_order': False, 'shape': ({dims}), }}",
        dtype.descr()
    );
    // magic (6) + version (2) + length (2) + dict + '\n'
    let unpadded = 10 + dict.len() + 1;
    dict.push_str(&" ".repeat(unpadded.next_multiple_of(64) - unpadded));
    dict.push('\n');
    let mut out = Vec::with_capacity(10 + dict.len());
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    // The dictionary of these arrays is well under 64 KiB.
    #[allow(clippy::cast_possible_truncation)]
    out.extend_from_slice(&(dict.len() as u16).to_le_bytes());
    out.extend_from_slice(dict.as_bytes());
    out
}

/// A whole `.npy` file: header and the little-endian data.
#[must_use]
pub fn file(dtype: Dtype, shape: &[usize], data: &[u8]) -> Vec<u8> {
    let mut out = header(dtype, shape);
    out.extend_from_slice(data);
    out
}

/// Appends `f32` values in little-endian order.
pub fn push_f32(buf: &mut Vec<u8>, values: &[f32]) {
    for v in values {
        buf.extend_from_slice(&v.to_le_bytes());
    }
}

/// Appends `u32` values in little-endian order.
pub fn push_u32(buf: &mut Vec<u8>, values: &[u32]) {
    for v in values {
        buf.extend_from_slice(&v.to_le_bytes());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_is_aligned_and_readable() {
        let h = header(Dtype::U8, &[3, 96, 96, 3]);
        assert_eq!(h.len() % 64, 0);
        let text = String::from_utf8_lossy(&h[10..]);
        assert!(
            text.starts_with("{'descr': '|u1', 'fortran_order': False, 'shape': (3, 96, 96, 3), }")
        );
        assert!(text.ends_with('\n'));
        let h = header(Dtype::F32, &[7]);
        assert!(String::from_utf8_lossy(&h).contains("'shape': (7,)"));
    }
}
