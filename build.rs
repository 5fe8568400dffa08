//! Records the git commit the crate is built from (`MONOLAYER_GIT_COMMIT`: 12 hex digits, or
//! "unknown" outside a git checkout), for the code version the page puts in its share links and
//! downloads and in every run.json (`src/formats/version.rs`).

use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    let out = Command::new("git").args(args).output().ok()?;
    out.status.success().then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

fn main() {
    let commit = git(&["rev-parse", "--short=12", "HEAD"]).unwrap_or_else(|| "unknown".into());
    println!("cargo:rustc-env=MONOLAYER_GIT_COMMIT={commit}");
    // Run again when HEAD moves: HEAD itself (a checkout) and the branch it names (a commit).
    // (Only files that exist: a missing one would make every build run this again.)
    let branch = git(&["symbolic-ref", "-q", "HEAD"]);
    let names = ["HEAD", "packed-refs"].into_iter().map(String::from).chain(branch);
    for path in names.filter_map(|name| git(&["rev-parse", "--git-path", &name])) {
        if std::path::Path::new(&path).exists() {
            println!("cargo:rerun-if-changed={path}");
        }
    }
    println!("cargo:rerun-if-changed=build.rs");
}
