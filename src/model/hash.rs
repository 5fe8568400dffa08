//! 64-bit FNV-1a: the one hash of the core, shared by [`Monolayer::fingerprint`] (a state's
//! bits) and the relaxed-state format (`formats::snapshot`: its keys and its checksum). Small,
//! the same on every target, and enough to tell parameter sets, damaged files and states apart (it is no defence against a forged file, which the page never loads).
//!
//! [`Monolayer::fingerprint`]: crate::model::monolayer::Monolayer::fingerprint

/// The offset basis of 64-bit FNV-1a, the hash of no bytes.
pub(crate) const FNV1A_START: u64 = 0xcbf2_9ce4_8422_2325;

/// 64-bit FNV-1a of `bytes`, continuing from the hash `h` of what came before them (start from
/// [`FNV1A_START`]).
pub(crate) fn fnv1a_continue(h: u64, bytes: &[u8]) -> u64 {
    bytes.iter().fold(h, |h, &b| (h ^ b as u64).wrapping_mul(0x0100_0000_01b3))
}

/// 64-bit FNV-1a of `bytes`.
pub(crate) fn fnv1a(bytes: &[u8]) -> u64 {
    fnv1a_continue(FNV1A_START, bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The published test vectors of FNV-1a 64: the hash every fingerprint and key is made of.
    #[test]
    fn fnv1a_matches_its_reference_values() {
        assert_eq!(fnv1a(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(fnv1a(b"a"), 0xaf63_dc4c_8601_ec8c);
        assert_eq!(fnv1a(b"foobar"), 0x8594_4171_f739_67e8);
        assert_eq!(fnv1a_continue(fnv1a(b"foo"), b"bar"), fnv1a(b"foobar"));
    }
}
