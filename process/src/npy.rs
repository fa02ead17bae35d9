//! Reader for NumPy `.npy` arrays of float64 (little- or big-endian, C or Fortran order,
//! format versions 1-3), enough for recorded signals saved with `numpy.save`.

use std::path::Path;

use crate::error::{ProcessError, Result};

/// A float64 array: shape and values in C (row-major) order.
#[derive(Debug, Clone, PartialEq)]
pub struct NpyArray {
    /// Dimensions.
    pub shape: Vec<usize>,
    /// Values, row-major (last index fastest).
    pub data: Vec<f64>,
}

impl NpyArray {
    /// Row `i` of a 2-D array.
    pub fn row(&self, i: usize) -> Option<&[f64]> {
        if self.shape.len() != 2 || i >= self.shape[0] {
            return None;
        }
        let n = self.shape[1];
        self.data.get(i * n..(i + 1) * n)
    }
}

/// Reads a `.npy` file.
pub fn read(path: &Path) -> Result<NpyArray> {
    let bytes = std::fs::read(path).map_err(|source| ProcessError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse(&bytes, &path.display().to_string())
}

fn err(file: &str, location: &str, message: impl Into<String>) -> ProcessError {
    ProcessError::Format {
        file: file.to_string(),
        location: location.to_string(),
        message: message.into(),
    }
}

/// Parses the bytes of a `.npy` file; `file` names it in errors.
pub fn parse(bytes: &[u8], file: &str) -> Result<NpyArray> {
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err(err(
            file,
            "magic",
            "not a NumPy .npy file (missing \\x93NUMPY magic); save it with numpy.save",
        ));
    }
    let major = bytes[6];
    let (header_len, start) = match major {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10usize),
        2 | 3 => {
            if bytes.len() < 12 {
                return Err(err(file, "header", "truncated header length"));
            }
            (
                u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
                12,
            )
        }
        v => {
            return Err(err(
                file,
                "version",
                format!("unsupported .npy format version {v}; re-save with numpy ≥ 1.0"),
            ))
        }
    };
    let end = start
        .checked_add(header_len)
        .filter(|e| *e <= bytes.len())
        .ok_or_else(|| err(file, "header", "truncated header"))?;
    let header = std::str::from_utf8(&bytes[start..end])
        .map_err(|_| err(file, "header", "header is not text"))?;
    let field = |key: &str| -> Result<&str> {
        let pat = format!("'{key}':");
        let at = header.find(&pat).ok_or_else(|| {
            err(
                file,
                "header",
                format!("no '{key}' entry in header {header:?}"),
            )
        })?;
        Ok(header[at + pat.len()..].trim_start())
    };
    let descr = field("descr")?;
    let little = if descr.starts_with("'<f8'") {
        true
    } else if descr.starts_with("'>f8'") {
        false
    } else {
        let shown: String = descr.chars().take(8).collect();
        return Err(err(
            file,
            "header 'descr'",
            format!(
                "dtype {shown} is not float64 ('<f8'/'>f8'); convert with arr.astype(np.float64)"
            ),
        ));
    };
    let fortran = field("fortran_order")?.starts_with("True");
    let shape_text = field("shape")?;
    let close = shape_text
        .find(')')
        .ok_or_else(|| err(file, "header 'shape'", "unterminated shape tuple"))?;
    let inner = shape_text
        .get(1..close)
        .ok_or_else(|| err(file, "header 'shape'", "malformed shape tuple"))?;
    let mut shape = Vec::new();
    for part in inner.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        shape.push(part.parse::<usize>().map_err(|_| {
            err(
                file,
                "header 'shape'",
                format!("dimension {part:?} is not a non-negative integer"),
            )
        })?);
    }
    let count = shape
        .iter()
        .try_fold(1usize, |a, d| a.checked_mul(*d))
        .ok_or_else(|| err(file, "header 'shape'", "shape overflows"))?;
    let body = &bytes[end..];
    let need = count
        .checked_mul(8)
        .ok_or_else(|| err(file, "header 'shape'", "shape overflows"))?;
    if body.len() != need {
        return Err(err(
            file,
            "data",
            format!(
                "holds {} bytes, the shape {:?} needs {need}: the file is truncated or corrupt",
                body.len(),
                shape
            ),
        ));
    }
    let mut data: Vec<f64> = body
        .chunks_exact(8)
        .map(|c| {
            let a = [c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]];
            if little {
                f64::from_le_bytes(a)
            } else {
                f64::from_be_bytes(a)
            }
        })
        .collect();
    if fortran && shape.len() > 1 {
        // Column-major -> row-major.
        let mut out = vec![0.0; count];
        let nd = shape.len();
        let mut idx = vec![0usize; nd];
        for v in data.iter() {
            let mut off = 0;
            for d in 0..nd {
                off = off * shape[d] + idx[d];
            }
            out[off] = *v;
            for d in 0..nd {
                idx[d] += 1;
                if idx[d] < shape[d] {
                    break;
                }
                idx[d] = 0;
            }
        }
        data = out;
    }
    Ok(NpyArray { shape, data })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn file(descr: &str, fortran: bool, shape: &str, data: &[f64]) -> Vec<u8> {
        let mut h = format!(
            "{{'descr': '{descr}', 'fortran_order': {}, 'shape': {shape}, }}",
            if fortran { "True" } else { "False" }
        );
        while (10 + h.len() + 1) % 64 != 0 {
            h.push(' ');
        }
        h.push('\n');
        let mut b = b"\x93NUMPY\x01\x00".to_vec();
        b.extend((h.len() as u16).to_le_bytes());
        b.extend(h.as_bytes());
        for v in data {
            b.extend(if descr == ">f8" {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            });
        }
        b
    }

    #[test]
    fn reads_c_and_fortran_order() {
        let c = parse(
            &file("<f8", false, "(2, 3)", &[1., 2., 3., 4., 5., 6.]),
            "c",
        )
        .unwrap();
        assert_eq!(c.shape, vec![2, 3]);
        assert_eq!(c.row(1).unwrap(), &[4., 5., 6.]);
        let f = parse(&file("<f8", true, "(2, 3)", &[1., 4., 2., 5., 3., 6.]), "f").unwrap();
        assert_eq!(f.data, c.data);
        let b = parse(&file(">f8", false, "(3,)", &[1., 2., 3.]), "b").unwrap();
        assert_eq!(b.data, vec![1., 2., 3.]);
    }

    #[test]
    fn rejects_wrong_dtype_and_truncation() {
        let e = parse(&file("<i8", false, "(1,)", &[1.0]), "x.npy")
            .unwrap_err()
            .to_string();
        assert!(e.contains("x.npy") && e.contains("float64"), "{e}");
        let mut t = file("<f8", false, "(4,)", &[1., 2., 3., 4.]);
        t.truncate(t.len() - 3);
        let e = parse(&t, "t.npy").unwrap_err().to_string();
        assert!(e.contains("truncated"), "{e}");
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 512, rng_seed: proptest::test_runner::RngSeed::Fixed(4), ..ProptestConfig::default() })]
        #[test]
        fn never_panics_on_garbage(bytes in proptest::collection::vec(any::<u8>(), 0..200), cut in 0usize..200) {
            let _ = parse(&bytes, "fuzz");
            let good = file("<f8", false, "(3,)", &[1., 2., 3.]);
            let mut m = good.clone();
            m.truncate(cut.min(good.len()));
            m.extend(&bytes);
            let _ = parse(&m, "fuzz");
        }
    }
}
