//! Fixed-size linear-algebra aliases (no heap allocation, deterministic kernels).
//!
//! The joint space has a fixed capacity [`NMAX`]; a model uses its leading `nv` entries
//! (`Model::nv`) and every loop of the core runs over `0..nv` only. The unused entries of a
//! [`VecN`] and the rows/columns `>= nv` of a [`MatN`] stay exactly 0.
//!
//! The small kernels below ([`mat_vec_row`], [`dot_n`], [`cholesky_solve`]) work on the
//! leading block and perform, for `n <= 8`, exactly the floating-point operations of
//! nalgebra's fixed-size `Matrix * Vector`, `dot` and `Cholesky::solve` on an n-sized
//! matrix, so the nominal 7-DOF model gives the same bits as when the chain was hard-wired
//! to `SMatrix<f64, 7, 7>`.

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

/// Capacity of the joint space: 3 motors + 28 link joints, e.g. a `beam(4)` link (16
/// joints) and a `beam(3)` link (12), or `beam(6)` (24) with a PRBM link and torsion joints.
/// A model's own `nv` is checked against it at compile time.
pub const NMAX: usize = 31;
/// Number of motor joints.
pub const NM: usize = 3;
/// Most segments per link: 3 for a multi-segment PRBM link, 2 per element of a beam link
/// (`higher_bending_modes.elements` ≤ [`NELEM_MAX`]).
pub const NSEG_MAX: usize = 2 * NELEM_MAX;
/// Most Euler–Bernoulli elements per beam link.
pub const NELEM_MAX: usize = 6;
/// Capacity of the bending-joint list: 2 links × [`NSEG_MAX`] universal joints × 2.
pub const NBMAX: usize = 2 * NSEG_MAX * 2;
/// Capacity of the passive-joint list (bending + torsion, the joints with a spring).
pub const NPMAX: usize = NBMAX + 2;
/// Joints of the arm file's chain (3 motors + one universal joint per link); the compiled
/// model expands it to `nv` joints.
pub const NV_SPEC: usize = 7;

/// 3-vector.
pub type Vec3 = Vector3<f64>;
/// 3×3 matrix.
pub type Mat3 = Matrix3<f64>;
/// Joint-space vector (capacity [`NMAX`]; entries `>= nv` are 0).
pub type VecN = SVector<f64, NMAX>;
/// Joint-space matrix (capacity [`NMAX`] × [`NMAX`]; rows/columns `>= nv` are 0).
pub type MatN = SMatrix<f64, NMAX, NMAX>;

/// Skew-symmetric matrix with `skew(a) * b = a × b`.
#[inline]
pub fn skew(a: &Vec3) -> Mat3 {
    Mat3::new(0.0, -a.z, a.y, a.z, 0.0, -a.x, -a.y, a.x, 0.0)
}

/// Rotation `Rot_z(θ) Rot_x(α)` from `(cos θ, sin θ, cos α, sin α)`.
#[inline]
pub fn rot_zx(ct: f64, st: f64, ca: f64, sa: f64) -> Mat3 {
    Mat3::new(ct, -st * ca, st * sa, st, ct * ca, -ct * sa, 0.0, sa, ca)
}

/// Rotation `Rot_x(θ)` from `(cos θ, sin θ)`.
#[inline]
pub fn rot_x(ct: f64, st: f64) -> Mat3 {
    Mat3::new(1.0, 0.0, 0.0, 0.0, ct, -st, 0.0, st, ct)
}

/// Row `i` of `m x` over the leading `n` columns: `Σ_j m_ij x_j`, summed in column order
/// starting from the first product (nalgebra's gemv order). `n >= 1`.
#[inline]
pub fn mat_vec_row(m: &MatN, x: &VecN, i: usize, n: usize) -> f64 {
    let mut y = m[(i, 0)] * x[0];
    for j in 1..n {
        y += m[(i, j)] * x[j];
    }
    y
}

/// `Σ_{k<n} a_k b_k`, summed in order from 0.0 (nalgebra's `dot` order for n < 8).
#[inline]
pub fn dot_n(a: &VecN, b: &VecN, n: usize) -> f64 {
    let mut s = 0.0;
    for k in 0..n {
        s += a[k] * b[k];
    }
    s
}

/// Solve `A x = b` in place for the symmetric positive-definite leading `n × n` block of `a`
/// (only its lower triangle is read) by Cholesky factorisation `A = L Lᵀ`; `a` is
/// overwritten by L (lower triangle), `b` by x. Entries of `b` beyond `n` are untouched.
/// Returns false (leaving `a`, `b` partly overwritten) when a pivot is zero, negative or
/// NaN, i.e. A is not positive definite.
///
/// Cost n³/6 multiply-adds; no allocation. The operations are those of nalgebra 0.35's
/// `Cholesky::new` + `solve` (column-by-column axpy updates, division by the pivot, forward
/// substitution with axpy, back substitution with in-order dot products; `y += a·x` is
/// nalgebra's `y = a·x + y`, IEEE addition being commutative), so the result is
/// bit-identical to `SMatrix<f64, n, n>::cholesky().solve()` for n < 9.
#[inline]
pub fn cholesky_solve(a: &mut MatN, b: &mut VecN, n: usize) -> bool {
    // one instance per chain length a PRBM model can have (7..=17), so that the loops have
    // compile-time trip counts (unrolled, no bounds checks) like the old fixed 7×7 solve;
    // longer (beam) chains use the general kernel
    match n {
        7 => chol_fixed::<7>(a, b),
        8 => chol_fixed::<8>(a, b),
        9 => chol_fixed::<9>(a, b),
        10 => chol_fixed::<10>(a, b),
        11 => chol_fixed::<11>(a, b),
        12 => chol_fixed::<12>(a, b),
        13 => chol_fixed::<13>(a, b),
        14 => chol_fixed::<14>(a, b),
        15 => chol_fixed::<15>(a, b),
        16 => chol_fixed::<16>(a, b),
        17 => chol_fixed::<17>(a, b),
        _ => chol_dyn(a, b, n),
    }
}

#[inline(always)]
fn chol_fixed<const N: usize>(a: &mut MatN, b: &mut VecN) -> bool {
    chol_dyn(a, b, N)
}

/// The kernel of [`cholesky_solve`] (column slices of the column-major storage).
#[inline(always)]
fn chol_dyn(a: &mut MatN, b: &mut VecN, n: usize) -> bool {
    assert!(n <= NMAX);
    // column j is data[j * NMAX .. (j + 1) * NMAX]
    let data = a.as_mut_slice();
    for j in 0..n {
        let (left, right) = data.split_at_mut(j * NMAX);
        let col_j = &mut right[j..n];
        for k in 0..j {
            let col_k = &left[k * NMAX + j..k * NMAX + n];
            let factor = -col_k[0];
            for (y, &x) in col_j.iter_mut().zip(col_k) {
                *y += factor * x;
            }
        }
        let diag = col_j[0];
        if diag.is_nan() || diag <= 0.0 {
            return false;
        }
        let denom = diag.sqrt();
        col_j[0] = denom;
        for y in &mut col_j[1..] {
            *y /= denom;
        }
    }
    let b = &mut b.as_mut_slice()[..n];
    // L y = b
    for i in 0..n {
        let col_i = &data[i * NMAX + i..i * NMAX + n];
        let coeff = b[i] / col_i[0];
        b[i] = coeff;
        for (y, &l) in b[i + 1..].iter_mut().zip(&col_i[1..]) {
            *y += -coeff * l;
        }
    }
    // Lᵀ x = y
    for i in (0..n).rev() {
        let col_i = &data[i * NMAX + i..i * NMAX + n];
        let mut dot = 0.0;
        for (&l, &y) in col_i[1..].iter().zip(&b[i + 1..]) {
            dot += l * y;
        }
        b[i] = (b[i] - dot) / col_i[0];
    }
    true
}

/// Eigenvalues of a real square matrix, from its real Schur form `A = Q T Qᵀ`.
///
/// Use this, not nalgebra 0.35's `complex_eigenvalues`: that one reads every 2×2 block
/// left on T's diagonal as a complex pair and takes `√(−discriminant)`, which is NaN when
/// the block's eigenvalues are real. Such a block is left whenever the QR iteration cannot
/// split a (nearly) defective real pair, e.g. the double zero eigenvalue of a motor joint
/// with no stiffness and no damping (an all-rigid arm without payload has one at q1: the
/// free rotation about the vertical axis, `[[0, 1], [ε, 0]]` with ε at rounding level).
/// Here a block with discriminant ≥ 0 gives its two real eigenvalues `tr/2 ± √disc`.
/// Non-finite entries of `a` give NaN eigenvalues (the Schur iteration is not run).
pub fn eigenvalues(a: nalgebra::DMatrix<f64>) -> Vec<nalgebra::Complex<f64>> {
    use nalgebra::Complex;
    let n = a.nrows();
    assert_eq!(n, a.ncols(), "eigenvalues of a non-square matrix");
    if n == 0 {
        return Vec::new();
    }
    if a.iter().any(|v| !v.is_finite()) {
        return vec![Complex::new(f64::NAN, f64::NAN); n];
    }
    let (_, t) = nalgebra::linalg::Schur::new(a).unpack();
    let mut out = Vec::with_capacity(n);
    let mut m = 0;
    while m < n {
        if m + 1 == n || t[(m + 1, m)] == 0.0 {
            out.push(Complex::new(t[(m, m)], 0.0));
            m += 1;
            continue;
        }
        // 2×2 block [[p, q], [r, s]]: λ = (p + s)/2 ± √(((p − s)/2)² + q r)
        let (p, q, r, s) = (t[(m, m)], t[(m, m + 1)], t[(m + 1, m)], t[(m + 1, m + 1)]);
        let half_tr = 0.5 * (p + s);
        let half_diff = 0.5 * (p - s);
        let disc = half_diff * half_diff + q * r;
        if disc >= 0.0 {
            let d = disc.sqrt();
            out.push(Complex::new(half_tr + d, 0.0));
            out.push(Complex::new(half_tr - d, 0.0));
        } else {
            let d = (-disc).sqrt();
            out.push(Complex::new(half_tr, d));
            out.push(Complex::new(half_tr, -d));
        }
        m += 2;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eigenvalues_of_real_2x2_blocks_are_real_not_nan() {
        use nalgebra::DMatrix;
        // a nilpotent-like block with a rounding-level lower entry: the eigenvalues are ±√ε
        for eps in [0.0, 1e-300, 1e-27, 1e-12] {
            let a = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, eps, 0.0]);
            let ev = eigenvalues(a);
            let mut re: Vec<f64> = ev.iter().map(|z| z.re).collect();
            re.sort_by(f64::total_cmp);
            assert!(ev.iter().all(|z| z.re.is_finite() && z.im == 0.0), "eps {eps}: {ev:?}");
            assert!((re[1] - eps.sqrt()).abs() <= 1e-15 && (re[0] + eps.sqrt()).abs() <= 1e-15, "eps {eps}: {ev:?}");
        }
        // a damped oscillator ẍ + 2ζω ẋ + ω² x = 0: λ = −ζω ± iω√(1 − ζ²)
        let (w, z) = (7.85_f64, 0.05_f64);
        let ev = eigenvalues(DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -w * w, -2.0 * z * w]));
        for l in &ev {
            assert!((l.re + z * w).abs() < 1e-12 && (l.im.abs() - w * (1.0 - z * z).sqrt()).abs() < 1e-12, "{ev:?}");
        }
        // random matrices: the same eigenvalues as the characteristic polynomial's check
        // det(A − λI) ≈ 0, and the sum equals the trace
        let mut s: u64 = 99;
        let mut r = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for n in [3usize, 6, 9] {
            let a = DMatrix::from_fn(n, n, |_, _| r());
            let ev = eigenvalues(a.clone());
            let tr: f64 = ev.iter().map(|z| z.re).sum();
            assert!((tr - a.trace()).abs() < 1e-10 && ev.iter().map(|z| z.im).sum::<f64>().abs() < 1e-10);
            for l in &ev {
                let ac = a.map(|v| nalgebra::Complex::new(v, 0.0)) - DMatrix::identity(n, n) * *l;
                assert!(ac.determinant().norm() < 1e-9, "n {n}: λ = {l}");
            }
        }
        assert!(eigenvalues(DMatrix::from_element(2, 2, f64::NAN)).iter().all(|z| z.re.is_nan()));
    }

    #[test]
    fn kernels_match_nalgebra_bits_for_7x7() {
        // random SPD 7×7 matrices in the leading block of a MatN
        let mut s: u64 = 12345;
        let mut r = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for _ in 0..50 {
            let g = SMatrix::<f64, 7, 7>::from_fn(|_, _| r());
            let a7 = g * g.transpose() + SMatrix::<f64, 7, 7>::identity() * 0.1;
            let b7 = SVector::<f64, 7>::from_fn(|_, _| r());
            let x7 = a7.cholesky().unwrap().solve(&b7);
            let a = MatN::from_fn(|i, j| if i < 7 && j < 7 { a7[(i, j)] } else { 0.0 });
            let b = VecN::from_fn(|i, _| if i < 7 { b7[i] } else { 0.0 });
            let (mut aa, mut x) = (a, b);
            assert!(cholesky_solve(&mut aa, &mut x, 7));
            for i in 0..7 {
                assert_eq!(x[i].to_bits(), x7[i].to_bits());
            }
            for i in 7..NMAX {
                assert_eq!(x[i], 0.0);
            }
            let y7 = a7 * b7;
            for i in 0..7 {
                assert_eq!(mat_vec_row(&a, &b, i, 7).to_bits(), y7[i].to_bits());
            }
            let yy = VecN::from_fn(|i, _| if i < 7 { y7[i] } else { 0.0 });
            assert_eq!(dot_n(&b, &yy, 7).to_bits(), b7.dot(&y7).to_bits());
        }
        // not positive definite
        let mut a = MatN::zeros();
        let mut b = VecN::zeros();
        a[(0, 0)] = 1.0;
        a[(1, 1)] = -1.0;
        assert!(!cholesky_solve(&mut a, &mut b, 2));
    }
}
