//! Checks of numpy inputs, each error naming the argument, the row and what was expected.

use numpy::{PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::PyResult;

fn error<T>(message: String) -> PyResult<T> {
    Err(PyValueError::new_err(message))
}

/// The index of the first number that is infinite or NaN (exponent bits all set).
/// Checked a block at a time without an early exit, by integer adds and ors that the
/// compiler turns into SIMD (SSE2 is enough): millions of ray coordinates are checked on
/// every call.
fn first_non_finite(values: &[f32]) -> Option<usize> {
    const BLOCK: usize = 256;
    const EXPONENT: u32 = 0x7f80_0000;
    // One more in the exponent's lowest bit carries into the sign bit only when all the
    // exponent bits are set.
    let carry = |v: &f32| (v.to_bits() & EXPONENT).wrapping_add(0x0080_0000);
    values.chunks(BLOCK).enumerate().find_map(|(block, chunk)| {
        let any = chunk.iter().fold(0, |acc, v| acc | carry(v)) >> 31 != 0;
        any.then(|| block * BLOCK + chunk.iter().position(|v| !v.is_finite()).unwrap())
    })
}

/// The rows of an `(n, 3)` float32 array as `[x, y, z]`, every number finite.
pub fn points<'a>(name: &str, array: &'a PyReadonlyArray2<'_, f32>) -> PyResult<&'a [[f32; 3]]> {
    finite_rows(name, array)
}

/// The rows of an `(n, 6)` float32 array of rays, each an origin then a direction (as
/// Open3D passes them), every number finite: read in place, not split into two copies.
pub fn rays<'a>(name: &str, array: &'a PyReadonlyArray2<'_, f32>) -> PyResult<&'a [[f32; 6]]> {
    finite_rows(name, array)
}

/// The rows of an `(n, N)` float32 array, every number finite.
fn finite_rows<'a, const N: usize>(
    name: &str,
    array: &'a PyReadonlyArray2<'_, f32>,
) -> PyResult<&'a [[f32; N]]> {
    let shape = array.shape();
    if shape[1] != N {
        return error(format!(
            "{name} must have shape (n, {N}), not ({}, {})",
            shape[0], shape[1]
        ));
    }
    let flat = array
        .as_slice()
        .map_err(|_| PyValueError::new_err(format!("{name} must be C-contiguous and aligned")))?;
    if let Some(i) = first_non_finite(flat) {
        return error(format!(
            "{name}[{}] = {:?} is not finite",
            i / N,
            &flat[i / N * N..i / N * N + N]
        ));
    }
    Ok(rows(flat))
}

/// The rows of an `(n, 3)` int64 array of indices, each in `0..count`.
pub fn faces<'a>(array: &'a PyReadonlyArray2<'_, i64>, count: usize) -> PyResult<&'a [[i64; 3]]> {
    let shape = array.shape();
    if shape[1] != 3 {
        return error(format!(
            "faces must have shape (n, 3) of vertex indices, not ({}, {})",
            shape[0], shape[1]
        ));
    }
    let flat = array
        .as_slice()
        .map_err(|_| PyValueError::new_err("faces must be C-contiguous and aligned"))?;
    if let Some(i) = flat.iter().position(|&v| v < 0 || v as u64 >= count as u64) {
        return error(format!(
            "faces[{}] refers to vertex {}, but there are {count} vertices (0..={})",
            i / 3,
            flat[i],
            count as i64 - 1
        ));
    }
    Ok(rows(flat))
}

/// The boxes of an `(n, 2, 3)` float32 array (min corner, max corner), finite, min <= max.
pub fn boxes<'a>(array: &'a PyReadonlyArray3<'_, f32>) -> PyResult<&'a [[f32; 6]]> {
    let shape = array.shape();
    if shape[1] != 2 || shape[2] != 3 {
        return error(format!(
            "boxes must have shape (n, 2, 3) (min and max corners), not ({}, {}, {})",
            shape[0], shape[1], shape[2]
        ));
    }
    let flat = array
        .as_slice()
        .map_err(|_| PyValueError::new_err("boxes must be C-contiguous and aligned"))?;
    let boxes: &[[f32; 6]] = rows(flat);
    for (i, b) in boxes.iter().enumerate() {
        if b.iter().any(|v| !v.is_finite()) || (0..3).any(|a| b[a] > b[a + 3]) {
            return error(format!(
                "boxes[{i}] = {b:?} must be finite with min <= max on every axis"
            ));
        }
    }
    Ok(boxes)
}

/// A per-ray `(n,)` float32 array, finite or +inf, not NaN.
pub fn per_ray<'a>(
    name: &str,
    array: &'a PyReadonlyArray1<'_, f32>,
    n: usize,
) -> PyResult<&'a [f32]> {
    let values = array
        .as_slice()
        .map_err(|_| PyValueError::new_err(format!("{name} must be C-contiguous and aligned")))?;
    if values.len() != n {
        return error(format!(
            "{name} must be a number or have one value per ray ({n}), not {}",
            values.len()
        ));
    }
    if let Some(i) = values.iter().position(|v| v.is_nan() || *v < 0.0) {
        return error(format!(
            "{name}[{i}] = {} must be >= 0 and not NaN",
            values[i]
        ));
    }
    Ok(values)
}

/// An affine transform from the rows of a (3, 4) float32 matrix (the top of a 4x4 matrix
/// acting on column vectors, as numpy, trimesh and Open3D write them).
pub fn affine(array: &PyReadonlyArray2<'_, f32>) -> PyResult<glam::Affine3A> {
    if array.shape() != [3, 4] {
        return error(format!(
            "transform must be a 4x4 or 3x4 matrix, not {:?}",
            array.shape()
        ));
    }
    let m = array.as_array();
    let column = |j: usize| glam::Vec3::new(m[[0, j]], m[[1, j]], m[[2, j]]);
    Ok(glam::Affine3A::from_mat3_translation(
        glam::Mat3::from_cols(column(0), column(1), column(2)),
        column(3),
    ))
}

/// Rows of `N` values of a flat array whose last dimensions hold `N` (checked above).
fn rows<T, const N: usize>(flat: &[T]) -> &[[T; N]] {
    let (rows, rest) = flat.as_chunks::<N>();
    debug_assert!(rest.is_empty());
    rows
}

#[cfg(test)]
mod tests {
    use super::first_non_finite;

    #[test]
    fn the_first_infinite_or_nan_number_is_found_in_any_block() {
        let mut values = vec![1.0f32; 1000];
        values[3] = f32::MAX;
        values[4] = -f32::MAX;
        values[5] = f32::MIN_POSITIVE / 2.0;
        assert_eq!(first_non_finite(&values), None);
        for (at, bad) in [
            (0, f32::NAN),
            (300, f32::INFINITY),
            (511, f32::NEG_INFINITY),
            (999, -f32::NAN),
        ] {
            let mut v = values.clone();
            v[at] = bad;
            assert_eq!(first_non_finite(&v), Some(at), "{bad} at {at}");
        }
    }
}
