//! The architecture in one test: `src/` has five layers and imports go downwards only,
//! model ← analysis, gpu ← run, web (gpu, the GPU stages, sits beside analysis). A `use` of a higher layer from a lower one fails here with the
//! file and the line, before it can tangle the physics core with files or the browser.

use std::fs;
use std::path::{Path, PathBuf};

fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for entry in fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
        let path = entry.unwrap().path();
        if path.is_dir() {
            out.extend(rust_files(&path));
        } else if path.extension().is_some_and(|x| x == "rs") {
            out.push(path);
        }
    }
    out.sort();
    out
}

/// Every line of the layer's files that names one of the `forbidden` layers as a path
/// (`crate::run`, `monolayer::web`, `super::super::run`, ...).
fn upward_references(layer: &str, forbidden: &[&str]) -> Vec<String> {
    upward_references_in(&Path::new(env!("CARGO_MANIFEST_DIR")).join("src").join(layer), forbidden)
}

fn upward_references_in(root: &Path, forbidden: &[&str]) -> Vec<String> {
    let mut found = Vec::new();
    for file in rust_files(root) {
        let text = fs::read_to_string(&file).unwrap();
        for (i, line) in text.lines().enumerate() {
            let code = line.split("//").next().unwrap_or("");
            for f in forbidden {
                let named = [format!("crate::{f}"), format!("monolayer::{f}"), format!("super::super::{f}")];
                if named.iter().any(|n| code.contains(n.as_str())) {
                    found.push(format!("{}:{}: {}", file.display(), i + 1, line.trim()));
                }
            }
        }
    }
    found
}

#[test]
fn model_uses_no_higher_layer() {
    let found = upward_references("model", &["analysis", "gpu", "run", "web"]);
    assert!(found.is_empty(), "model/ must not import analysis/, gpu/, run/ or web/:\n{}", found.join("\n"));
}

#[test]
fn analysis_uses_neither_gpu_nor_run_nor_web() {
    let found = upward_references("analysis", &["gpu", "run", "web"]);
    assert!(found.is_empty(), "analysis/ must not import gpu/, run/ or web/:\n{}", found.join("\n"));
}

/// The GPU stages read the model (its parameters, cells and patches) and nothing else: they are
/// a second engine for the same physics, below the layers that would drive them.
#[test]
fn gpu_uses_only_the_model() {
    let found = upward_references("gpu", &["analysis", "run", "web"]);
    assert!(found.is_empty(), "gpu/ may import only model/:\n{}", found.join("\n"));
}

#[test]
fn run_and_web_do_not_use_each_other() {
    let mut found = upward_references("run", &["web"]);
    found.extend(upward_references("web", &["run"]));
    assert!(found.is_empty(), "run/ and web/ are siblings:\n{}", found.join("\n"));
}

#[test]
fn the_layers_are_the_folders_of_src() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut dirs: Vec<String> = fs::read_dir(&src)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_dir())
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    dirs.sort();
    assert_eq!(dirs, ["analysis", "gpu", "model", "run", "web"]);
    let loose: Vec<String> = fs::read_dir(&src)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file())
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .filter(|n| n != "lib.rs" && n != "main.rs")
        .collect();
    assert!(loose.is_empty(), "every module belongs to a layer folder: {loose:?}");
}

/// The check itself must be able to fail: an upward import is found, a comment is not.
#[test]
fn an_upward_import_is_detected() {
    let dir = tempfile::tempdir().unwrap();
    let nested = dir.path().join("sub");
    fs::create_dir(&nested).unwrap();
    fs::write(nested.join("x.rs"), "use crate::run::files::write_atomic;\n// crate::web in a comment is fine\n")
        .unwrap();
    fs::write(dir.path().join("y.rs"), "fn f() { monolayer::web::start() }\n").unwrap();
    let found = upward_references_in(dir.path(), &["run", "web"]);
    assert_eq!(found.len(), 2, "{found:?}");
    assert!(found[0].contains("x.rs:1"), "{found:?}");
}
