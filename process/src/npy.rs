//! NumPy `.npy` arrays of float64 (little- or big-endian, C or Fortran order, format versions
//! 1-3), as recorded signals are saved with `numpy.save`; the format itself is read by `npyz`.

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

/// Parses the bytes of a `.npy` file named `file` (for messages).
pub fn parse(bytes: &[u8], file: &str) -> Result<NpyArray> {
    let npy = npyz::NpyFile::new(bytes)
        .map_err(|e| err(file, "header", format!("not a NumPy .npy file: {e}")))?;
    let float64 = matches!(
        npy.dtype(),
        npyz::DType::Plain(t) if t.type_char() == npyz::TypeChar::Float && t.size_field() == 8
    );
    if !float64 {
        return Err(err(
            file,
            "header",
            format!(
                "dtype {} is not float64; save the array with dtype=np.float64",
                npy.dtype().descr()
            ),
        ));
    }
    let shape: Vec<usize> = npy.shape().iter().map(|&d| d as usize).collect();
    let fortran = npy.order() == npyz::Order::Fortran;
    let n: usize = shape.iter().product();
    let data = npy.into_vec::<f64>().map_err(|e| {
        err(
            file,
            "data",
            format!("truncated or unreadable data ({n} values expected): {e}"),
        )
    })?;
    if data.len() != n {
        return Err(err(
            file,
            "data",
            format!("truncated: {} of {n} values", data.len()),
        ));
    }
    let data = if fortran {
        to_c_order(&data, &shape)
    } else {
        data
    };
    Ok(NpyArray { shape, data })
}

/// Column-major (Fortran) values of an array of `shape` in row-major (C) order.
fn to_c_order(data: &[f64], shape: &[usize]) -> Vec<f64> {
    let nd = shape.len();
    let mut out = vec![0.0; data.len()];
    // Walk the Fortran order (first index fastest), placing each value at its C offset.
    let mut idx = vec![0usize; nd];
    for v in data {
        let off = idx.iter().zip(shape).fold(0, |off, (i, n)| off * n + i);
        out[off] = *v;
        for d in 0..nd {
            idx[d] += 1;
            if idx[d] < shape[d] {
                break;
            }
            idx[d] = 0;
        }
    }
    out
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
