//! In-place Gauss-Jordan inversion of small fixed-size matrices, returning log|det|.
//!
//! The sign-function iterations need both the inverse and the determinant (for the
//! scaling); a single Gauss-Jordan sweep gives both without any heap memory. The
//! determinant is returned as a logarithm because det of a 24x24 iterate easily
//! overflows an f64.

use nalgebra::SMatrix;

/// Why an inversion failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum InversionError {
    /// A pivot fell below `N * eps * max|a_ij|`: the matrix is numerically singular.
    Singular,
    /// The matrix holds NaN or infinite entries.
    NotFinite,
}

/// Inverts `a` in place (Gauss-Jordan with partial pivoting) and returns ln|det(a)|.
///
/// On error `a` holds garbage and must not be used.
pub(crate) fn invert_in_place<const N: usize>(
    a: &mut SMatrix<f64, N, N>,
) -> Result<f64, InversionError> {
    // The checks on the storage slice (nalgebra's element iterator costs more than the
    // elimination on small matrices); every entry is finite past the first, so the largest
    // magnitude is the same number in any order (`amax`'s).
    let entries = a.as_slice();
    if entries.iter().any(|v| !v.is_finite()) {
        return Err(InversionError::NotFinite);
    }
    let scale = entries.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let tiny = scale * f64::EPSILON * N as f64;
    if scale == 0.0 {
        return Err(InversionError::Singular);
    }
    let mut row_swaps = [0usize; N];
    let mut factors = [0.0f64; N];
    let mut log_det = 0.0;
    for k in 0..N {
        // Partial pivoting: largest magnitude in column k at or below the diagonal.
        let mut pivot_row = k;
        let mut pivot_abs = a[(k, k)].abs();
        for i in k + 1..N {
            let v = a[(i, k)].abs();
            if v > pivot_abs {
                pivot_abs = v;
                pivot_row = i;
            }
        }
        if pivot_abs <= tiny || pivot_abs.is_nan() {
            return Err(InversionError::Singular);
        }
        row_swaps[k] = pivot_row;
        if pivot_row != k {
            a.swap_rows(k, pivot_row);
        }
        log_det += pivot_abs.ln();
        let pivot_inv = 1.0 / a[(k, k)];
        a[(k, k)] = 1.0;
        for j in 0..N {
            a[(k, j)] *= pivot_inv;
        }
        for i in 0..N {
            factors[i] = if i == k { 0.0 } else { a[(i, k)] };
            if i != k {
                a[(i, k)] = 0.0;
            }
        }
        // Column-major friendly elimination: the inner loop walks down one column (a slice
        // of the column-major storage: the same `c -= f * p` per element as indexing does,
        // without the per-element index arithmetic).
        for column in a.as_mut_slice().chunks_exact_mut(N) {
            let pivot_row_value = column[k];
            if pivot_row_value != 0.0 {
                for (c, f) in column.iter_mut().zip(factors.iter()) {
                    *c -= f * pivot_row_value;
                }
            }
        }
    }
    // Undo the row swaps as column swaps of the inverse, in reverse order.
    for k in (0..N).rev() {
        if row_swaps[k] != k {
            a.swap_columns(k, row_swaps[k]);
        }
    }
    Ok(log_det)
}

/// `out = a * b` with every element summed as nalgebra's product of statically sized
/// matrices sums it (`a[i,0]*b[0,j]`, then `+ a[i,k]*b[k,j]` for k = 1, 2, ... in order), so
/// the result is bit-for-bit `a * b`, written into `out` (no temporary, no copy).
pub(crate) fn mul_into<const R: usize, const K: usize, const C: usize>(
    a: &SMatrix<f64, R, K>,
    b: &SMatrix<f64, K, C>,
    out: &mut SMatrix<f64, R, C>,
) {
    if K == 0 {
        out.fill(0.0);
        return;
    }
    let a = a.as_slice();
    let b = b.as_slice();
    for (column, b_column) in out
        .as_mut_slice()
        .chunks_exact_mut(R)
        .zip(b.chunks_exact(K))
    {
        let first = b_column[0];
        for (o, x) in column.iter_mut().zip(a[..R].iter()) {
            *o = x * first;
        }
        for (a_column, &bk) in a.chunks_exact(R).zip(b_column.iter()).skip(1) {
            for (o, x) in column.iter_mut().zip(a_column.iter()) {
                *o += x * bk;
            }
        }
    }
}

/// `out = aᵀ` (a copy, no arithmetic).
pub(crate) fn transpose_into<const N: usize>(a: &SMatrix<f64, N, N>, out: &mut SMatrix<f64, N, N>) {
    for j in 0..N {
        for i in 0..N {
            out[(i, j)] = a[(j, i)];
        }
    }
}

/// Largest absolute column sum (the induced 1-norm).
pub(crate) fn norm1<const R: usize, const C: usize>(a: &SMatrix<f64, R, C>) -> f64 {
    let mut best = 0.0f64;
    // the columns of the column-major storage, each summed top to bottom (as a column view)
    for column in a.as_slice().chunks_exact(R) {
        let s: f64 = column.iter().map(|v| v.abs()).sum();
        if s > best || s.is_nan() {
            best = s;
        }
    }
    best
}

/// [`norm1`] over nalgebra's column views (the plain form it is tested against).
#[cfg(test)]
fn norm1_reference<const R: usize, const C: usize>(a: &SMatrix<f64, R, C>) -> f64 {
    let mut best = 0.0f64;
    for column in a.column_iter() {
        let s: f64 = column.iter().map(|v| v.abs()).sum();
        if s > best || s.is_nan() {
            best = s;
        }
    }
    best
}

/// [`invert_in_place`] with the elimination written with nalgebra's column views (the plain
/// form the slice loop is tested against bit for bit).
#[cfg(test)]
fn invert_in_place_reference<const N: usize>(
    a: &mut SMatrix<f64, N, N>,
) -> Result<f64, InversionError> {
    if a.iter().any(|v| !v.is_finite()) {
        return Err(InversionError::NotFinite);
    }
    let scale = a.amax();
    let tiny = scale * f64::EPSILON * N as f64;
    if scale == 0.0 {
        return Err(InversionError::Singular);
    }
    let mut row_swaps = [0usize; N];
    let mut factors = [0.0f64; N];
    let mut log_det = 0.0;
    for k in 0..N {
        let mut pivot_row = k;
        let mut pivot_abs = a[(k, k)].abs();
        for i in k + 1..N {
            let v = a[(i, k)].abs();
            if v > pivot_abs {
                pivot_abs = v;
                pivot_row = i;
            }
        }
        if pivot_abs <= tiny || pivot_abs.is_nan() {
            return Err(InversionError::Singular);
        }
        row_swaps[k] = pivot_row;
        if pivot_row != k {
            a.swap_rows(k, pivot_row);
        }
        log_det += pivot_abs.ln();
        let pivot_inv = 1.0 / a[(k, k)];
        a[(k, k)] = 1.0;
        for j in 0..N {
            a[(k, j)] *= pivot_inv;
        }
        for i in 0..N {
            factors[i] = if i == k { 0.0 } else { a[(i, k)] };
            if i != k {
                a[(i, k)] = 0.0;
            }
        }
        for j in 0..N {
            let pivot_row_value = a[(k, j)];
            if pivot_row_value != 0.0 {
                let mut column = a.column_mut(j);
                for i in 0..N {
                    column[i] -= factors[i] * pivot_row_value;
                }
            }
        }
    }
    for k in (0..N).rev() {
        if row_swaps[k] != k {
            a.swap_columns(k, row_swaps[k]);
        }
    }
    Ok(log_det)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix4;

    #[test]
    fn norm1_is_bitwise_the_reference() {
        let mut state = 9u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        for trial in 0..300usize {
            let mut a = SMatrix::<f64, 12, 12>::from_fn(|_, _| next() * 1e3);
            match trial % 6 {
                0 => a[(trial % 12, 3)] = f64::NAN,
                1 => a[(2, trial % 12)] = f64::INFINITY,
                2 => a.fill(-0.0),
                _ => {}
            }
            assert_eq!(norm1(&a).to_bits(), norm1_reference(&a).to_bits());
            let b = SMatrix::<f64, 4, 12>::from_fn(|_, _| next());
            assert_eq!(norm1(&b).to_bits(), norm1_reference(&b).to_bits());
        }
    }

    #[test]
    fn inverse_is_bitwise_the_reference() {
        let mut state = 3u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        for trial in 0..500usize {
            let mut a =
                SMatrix::<f64, 12, 12>::from_fn(|_, _| next() * 10f64.powi((trial % 7) as i32 - 3));
            if trial % 5 == 0 {
                a[(trial % 12, (trial / 3) % 12)] = 0.0; // zero pivot-row entries
            }
            if trial % 13 == 0 {
                a[(trial % 12, 0)] = [f64::NAN, f64::INFINITY][trial % 2]; // not finite
            }
            if trial % 11 == 0 {
                let row = a.row(1).into_owned();
                a.set_row(4, &row); // singular
            }
            let mut fast = a;
            let mut plain = a;
            let r1 = invert_in_place(&mut fast);
            let r2 = invert_in_place_reference(&mut plain);
            assert_eq!(r1.map(f64::to_bits), r2.map(f64::to_bits));
            if r1.is_ok() {
                let b1: Vec<u64> = fast.iter().map(|v| v.to_bits()).collect();
                let b2: Vec<u64> = plain.iter().map(|v| v.to_bits()).collect();
                assert_eq!(b1, b2, "trial {trial}");
            }
            let mut big = SMatrix::<f64, 24, 24>::from_fn(|_, _| next());
            let mut big_plain = big;
            assert_eq!(
                invert_in_place(&mut big).map(f64::to_bits),
                invert_in_place_reference(&mut big_plain).map(f64::to_bits)
            );
            assert_eq!(big, big_plain);
        }
    }

    #[test]
    fn inverse_and_log_det_match_nalgebra() {
        let a = Matrix4::new(
            0.0, 2.0, 1.0, 3.0, 1.0, -1.0, 0.5, 2.0, 4.0, 0.3, -2.0, 1.0, 1.5, 2.5, 0.7, -3.0,
        );
        let mut inv = a;
        let log_det = invert_in_place(&mut inv).expect("regular");
        let reference = a.try_inverse().expect("regular");
        assert!((inv - reference).amax() < 1e-12);
        assert!((log_det - a.determinant().abs().ln()).abs() < 1e-12);
    }

    #[test]
    fn singular_and_nan_are_reported() {
        let mut singular = Matrix4::<f64>::from_element(1.0);
        assert_eq!(
            invert_in_place(&mut singular),
            Err(InversionError::Singular)
        );
        let mut nan = Matrix4::<f64>::identity();
        nan[(2, 1)] = f64::NAN;
        assert_eq!(invert_in_place(&mut nan), Err(InversionError::NotFinite));
    }
}

#[cfg(test)]
mod large_tests {
    use super::*;

    #[test]
    fn inverse_of_24x24_matches_nalgebra() {
        let a = SMatrix::<f64, 24, 24>::from_fn(|i, j| {
            ((i * 7 + j * 13) % 17) as f64 - 8.0 + if i == j { 0.5 } else { 0.0 }
        });
        let mut inv = a;
        let log_det = invert_in_place(&mut inv).expect("regular");
        let reference = a.try_inverse().expect("regular");
        assert!(
            (inv - reference).amax() < 1e-9 * reference.amax(),
            "{}",
            (inv - reference).amax()
        );
        assert!((log_det - a.determinant().abs().ln()).abs() < 1e-9);
    }
}
