//! Sums over a patch or the lattice in a fixed order that runs in SIMD lanes.
//!
//! A plain `iter().sum()` of f64 adds one term after another: one dependency chain that waits
//! for each addition's latency and uses one lane. Here every sum keeps [`LANES`] partial sums,
//! term k going to partial sum k mod LANES, and adds them in a fixed tree at the end
//! ([`combine`]). The order depends only on the length, so the bits are the same for any thread
//! count and on every target (the lanes are IEEE operations; nothing is fused or reordered).
//! Used by the areas A_i, the shape tensors Q_i and the friction solve's inner products.

/// Partial sums per reduction: eight f64 chains fill four SSE or two AVX registers, enough to
/// hide the addition's latency.
pub const LANES: usize = 8;

/// Σ_k term(a_k) in the lanes' order ([`sum_pairs`] of the slice with itself).
#[inline(always)]
pub fn sum_of<A: Copy>(a: &[A], term: impl Fn(A) -> f64) -> f64 {
    sum_pairs(a, a, |x, _| term(x))
}

/// Σ_k term(a_k, b_k) over two slices of one length, in the lanes' order.
#[inline(always)]
pub fn sum_pairs<A: Copy, B: Copy>(a: &[A], b: &[B], term: impl Fn(A, B) -> f64) -> f64 {
    assert_eq!(a.len(), b.len(), "sum_pairs: slices of different lengths");
    let mut acc = [0.0f64; LANES];
    let whole = a.len() - a.len() % LANES;
    for (ca, cb) in a[..whole].chunks_exact(LANES).zip(b[..whole].chunks_exact(LANES)) {
        for k in 0..LANES {
            acc[k] += term(ca[k], cb[k]);
        }
    }
    for (k, (&x, &y)) in a[whole..].iter().zip(&b[whole..]).enumerate() {
        acc[k] += term(x, y);
    }
    combine(acc)
}

/// The partial sums added in a fixed tree.
#[inline(always)]
pub fn combine(acc: [f64; LANES]) -> f64 {
    ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every term once, in lane k mod LANES: integers sum exactly, and a rounding term shows
    /// the order (it differs from the sequential sum's for these lengths).
    #[test]
    fn sums_every_term_once_in_the_lanes_order() {
        for len in [0, 1, 7, 8, 9, 140, 1001] {
            let a: Vec<f64> = (0..len).map(|k| 1.0 + k as f64).collect();
            let ones = vec![1.0; len];
            let exact = (len * (len + 1) / 2) as f64;
            assert_eq!(sum_of(&a, |x| x), exact, "length {len}");
            assert_eq!(sum_pairs(&a, &ones, |x, y| x * y), exact, "length {len}");
            let mut acc = [0.0; LANES];
            for (k, x) in a.iter().enumerate() {
                acc[k % LANES] += x * 0.1;
            }
            assert_eq!(sum_of(&a, |x| x * 0.1).to_bits(), combine(acc).to_bits(), "length {len}");
            assert_eq!(sum_pairs(&a, &ones, |x, y| x * y * 0.1).to_bits(), combine(acc).to_bits());
        }
        // One large term, then ones: one after another, each 1 is lost beside 1e16 (half its
        // spacing of 2); in lanes seven of them add up on their own first.
        let mut a = vec![1.0; 9];
        a[0] = 1e16;
        assert_eq!(a.iter().sum::<f64>(), 1e16);
        assert_eq!(sum_of(&a, |x| x), 1e16 + 6.0);
    }

    #[test]
    #[should_panic(expected = "different lengths")]
    fn slices_must_match() {
        sum_pairs(&[1.0, 2.0], &[1.0], |x: f64, y: f64| x * y);
    }
}
