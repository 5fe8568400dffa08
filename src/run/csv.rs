//! How the run layer's CSV tables print a measurement that may be missing: an empty cell, so
//! that pandas and NumPy read it as NaN.

/// `v` with `decimals` decimals, or an empty cell when there is none.
pub(crate) fn cell(v: Option<f64>, decimals: usize) -> String {
    v.map(|x| format!("{x:.decimals$}")).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::cell;

    #[test]
    fn a_missing_value_is_an_empty_cell_and_a_value_has_its_decimals() {
        assert_eq!(cell(None, 6), "");
        assert_eq!(cell(Some(0.5), 6), "0.500000");
        assert_eq!(cell(Some(1.0 / 3.0), 4), "0.3333");
    }
}
