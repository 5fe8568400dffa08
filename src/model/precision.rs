//! The storage precision of each cell's per-site fields.
//!
//! Everything outside the friction solve streams the nine per-site fields of every cell's patch
//! (φ_i, its Heun copies, μ_i, f_i, v_i, ∂_t φ_i) several times per step, and is limited by
//! memory traffic, not arithmetic. [`Store`] is the type those fields are kept in; every
//! computation on them loads into f64, computes in f64, and rounds once on the store. Sums over
//! sites (areas, shape integrals), the lattice fields and the friction solve stay in f64.
//!
//! Which precision is the default, and the comparison that decided it, is in
//! docs/performance.md ("Storage precision"). The feature `f32-storage` selects f32.

/// A per-site storage type: loads into f64 exactly, and rounds an f64 to nearest on the store.
pub trait Real: Copy + Default + Into<f64> + PartialEq + std::fmt::Debug + Send + Sync + 'static {
    /// The nearest value of this type (round to nearest even; exact for f64).
    fn from_f64(x: f64) -> Self;
}

impl Real for f64 {
    #[inline(always)]
    fn from_f64(x: f64) -> Self {
        x
    }
}

impl Real for f32 {
    #[inline(always)]
    fn from_f64(x: f64) -> Self {
        x as f32
    }
}

/// The type of every per-site field of a cell.
#[cfg(feature = "f32-storage")]
pub type Store = f32;
/// The type of every per-site field of a cell.
#[cfg(not(feature = "f32-storage"))]
pub type Store = f64;

/// A short name of [`Store`] for records and reports ("f32" or "f64").
pub const STORE_NAME: &str = if std::mem::size_of::<Store>() == 4 { "f32" } else { "f64" };

/// x as an f64 (exact).
#[inline(always)]
pub fn load<T: Real>(x: T) -> f64 {
    x.into()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loads_are_exact_and_stores_round_to_nearest() {
        let x = 0.1_f64;
        assert_eq!(load(f64::from_f64(x)), x);
        let r = f32::from_f64(x);
        assert_eq!(r, 0.1_f32);
        // The f32 nearest to 0.1 is within half an ulp (2^-28 at this magnitude).
        assert!((load(r) - x).abs() <= 2f64.powi(-28));
        assert_eq!(load(f32::from_f64(1.0 + 2f64.powi(-30))), 1.0);
    }
}
