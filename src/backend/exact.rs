//! Exact-sign arithmetic for the watertight ray/triangle test (`triangle.rs`): Shewchuk's
//! error-free transforms (FMA two-product, two-sum, two-diff) and `diff_of_products`, the
//! 2x2 determinant `p * q - r * s` whose sign is always exact. Kept apart from the geometry
//! because its correctness is arithmetic alone, and is tested as such (against i128).

#[inline(always)]
fn two_prod(a: f64, b: f64) -> (f64, f64) {
    let x = a * b;
    (x, a.mul_add(b, -x))
}

#[inline(always)]
fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let x = a + b;
    let bv = x - a;
    let av = x - bv;
    (x, (a - av) + (b - bv))
}

#[inline(always)]
fn two_diff(a: f64, b: f64) -> (f64, f64) {
    let x = a - b;
    let bv = a - x;
    let av = x + bv;
    (x, (a - av) + (bv - b))
}

/// `p * q - r * s` with the exact sign: the largest component of the exact four-term
/// nonoverlapping expansion (0.0 exactly when the exact value is 0; NaN propagates).
#[cold]
#[inline(never)]
fn diff_of_products_exact(p: f64, q: f64, r: f64, s: f64) -> f64 {
    let (a1, a0) = two_prod(p, q);
    let (b1, b0) = two_prod(r, s);
    // Two_Two_Diff(a1, a0, b1, b0) -> (x3, x2, x1, x0), increasing magnitude.
    let (i, x0) = two_diff(a0, b0);
    let (j, r0) = two_sum(a1, i);
    let (i2, x1) = two_diff(r0, b1);
    let (x3, x2) = two_sum(j, i2);
    for c in [x3, x2, x1, x0] {
        if c != 0.0 {
            return c; // also returns NaN
        }
    }
    0.0
}

/// Relative bound under which the sign of the plain f64 `p*q - r*s` is not trusted.
const DOP_ERR: f64 = 2.0 * f64::EPSILON;

/// The plain f64 `p * q - r * s` when its sign is certain (it is then nonzero).
#[inline(always)]
fn diff_of_products_plain(p: f64, q: f64, r: f64, s: f64) -> Option<f64> {
    let pq = p * q;
    let rs = r * s;
    let d = pq - rs;
    (d.abs() > DOP_ERR * (pq.abs() + rs.abs()) + f64::MIN_POSITIVE).then_some(d)
}

/// `p * q - r * s`: the plain f64 value when its sign is certain, else the exact-sign value.
/// Antisymmetric: `diff_of_products(r, s, p, q) == -diff_of_products(p, q, r, s)`.
#[inline(always)]
pub(crate) fn diff_of_products(p: f64, q: f64, r: f64, s: f64) -> f64 {
    diff_of_products_plain(p, q, r, s).unwrap_or_else(|| diff_of_products_exact(p, q, r, s))
}

/// Whether `p * q - r * s` is nonzero by its plain f64 value alone (false: not known without
/// the exact expansion).
#[inline(always)]
pub(crate) fn certainly_nonzero(p: f64, q: f64, r: f64, s: f64) -> bool {
    diff_of_products_plain(p, q, r, s).is_some()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::raycast::test_support::Rng;

    /// The edge function's sign is exact where plain f64 rounds to 0 or to the wrong sign,
    /// checked against i128 arithmetic on random 40-bit integers times powers of two.
    #[test]
    fn diff_of_products_has_the_exact_sign() {
        let e = 2f64.powi(-30);
        // (1 + e)(1 - e) - 1 = -e^2: plain f64 says 0.
        assert_eq!((1.0 + e) * (1.0 - e) - 1.0, 0.0);
        assert!(diff_of_products(1.0 + e, 1.0 - e, 1.0, 1.0) < 0.0);
        assert!(diff_of_products(1.0, 1.0, 1.0 + e, 1.0 - e) > 0.0);
        assert_eq!(diff_of_products(3.0, 5.0, 5.0, 3.0), 0.0);
        let mut rng = Rng(99);
        let mut fallbacks = 0;
        for _ in 0..200_000 {
            let base = (rng.next_u64() >> 24) as i128; // 40 bits
            let m = |rng: &mut Rng| base + (rng.next_u64() % 3) as i128 - 1;
            let (p, q, r, s) = (m(&mut rng), m(&mut rng), m(&mut rng), m(&mut rng));
            let want = (p * q - r * s).signum();
            let k = 2f64.powi(rng.below(40) as i32 - 20);
            let got = diff_of_products(p as f64 * k, q as f64, r as f64 * k, s as f64);
            let plain = (p as f64 * k) * q as f64 - (r as f64 * k) * s as f64;
            if plain.signum() as i128 != want || plain == 0.0 {
                fallbacks += 1;
            }
            let sign = if got > 0.0 { 1 } else if got < 0.0 { -1 } else { 0 };
            assert_eq!(sign, want, "{p} {q} {r} {s}");
            assert_eq!(diff_of_products(r as f64 * k, s as f64, p as f64 * k, q as f64), -got);
        }
        assert!(fallbacks > 1000, "{fallbacks}");
    }

    /// The plain f64 value is trusted (no exact expansion) once the products differ by more
    /// than a few ulps of their size, and not where rounding could hide the sign.
    #[test]
    fn the_plain_value_is_trusted_only_beyond_its_rounding_bound() {
        assert!(certainly_nonzero(3.0, 1.0, 1.0, 1.0));
        assert!(certainly_nonzero(1.0, 1.0 + 1e-12, 1.0, 1.0));
        assert!(certainly_nonzero(-2.5, 4.0, 7.0, 1.5));
        let e = 2f64.powi(-30);
        assert!(!certainly_nonzero(1.0 + e, 1.0 - e, 1.0, 1.0));
        assert!(!certainly_nonzero(3.0, 5.0, 5.0, 3.0));
        // 8 ulps apart is trusted, 1 ulp (within the 2-epsilon bound of the sum) is not.
        assert!(certainly_nonzero(1.0, 1.0 + 8.0 * f64::EPSILON, 1.0, 1.0));
        assert!(!certainly_nonzero(1.0, 1.0 + f64::EPSILON, 1.0, 1.0));
        // The bound scales with the products' size (their sum, not their product): the same
        // at 2^20.
        let k = 1024.0;
        assert!(certainly_nonzero(k, k * (1.0 + 8.0 * f64::EPSILON), k, k));
        assert!(!certainly_nonzero(k, k * (1.0 + f64::EPSILON), k, k));
    }
}
