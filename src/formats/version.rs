//! The code version every file records (`run.json`'s `version`, the page's readout CSV and share
//! links): the crate version and the git commit it was built from (`build.rs`), e.g.
//! `0.1.0+f1cefbb1a2b3`. The same string natively and in the page.

/// The crate's version, from Cargo.toml.
pub const CRATE_VERSION: &str = env!("CARGO_PKG_VERSION");
/// 12 hex digits of the commit, or "unknown" when built outside a git checkout.
pub const GIT_COMMIT: &str = env!("MONOLAYER_GIT_COMMIT");

/// `<crate version>+<git commit>`.
pub fn code_version() -> String {
    format!("{CRATE_VERSION}+{GIT_COMMIT}")
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_version_names_the_crate_and_a_commit() {
        let v = super::code_version();
        let (crate_version, commit) = v.split_once('+').unwrap();
        assert_eq!(crate_version, env!("CARGO_PKG_VERSION"));
        assert!(commit == "unknown" || (commit.len() == 12 && commit.chars().all(|c| c.is_ascii_hexdigit())), "{v}");
    }
}
