//! The architecture in one test: `src/` has six layers and imports go downwards only,
//! model ← analysis, formats, gpu ← run, web (analysis, the file formats and the GPU stages sit
//! side by side on the model). An import of a higher layer from a lower one (whole, grouped, or
//! through a re-export) fails here with the file, the file it reaches and the path, before it can
//! tangle the physics core with files or the browser. And no files import each other around a
//! circle, inside a layer either.

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

/// Every import of the layer's files that leads to a file of one of the `forbidden` layers:
/// `from -> to (the path as written)`. Imports are read as the circle check below reads them
/// (whole paths, grouped `use` trees, `super::`, paths written in the code) and followed through
/// re-exports, so `crate::{run::RunDir}` and a `crate::X` that the crate's root re-exports from
/// `run` are found as `crate::run::RunDir` is.
fn upward_references(layer: &str, forbidden: &[&str]) -> Vec<String> {
    upward_references_in(&Path::new(env!("CARGO_MANIFEST_DIR")).join("src"), layer, forbidden)
}

fn upward_references_in(src: &Path, layer: &str, forbidden: &[&str]) -> Vec<String> {
    let (files, edges) = import_graph(src);
    let rel = |f: usize| files[f].strip_prefix(src).unwrap().to_path_buf();
    // A file's layer: the folder of `src/` it is in (none for lib.rs and main.rs).
    let layer_of = |f: usize| {
        let r = rel(f);
        let mut parts = r.iter();
        match (parts.next(), parts.next()) {
            (Some(dir), Some(_)) => Some(dir.to_string_lossy().into_owned()),
            _ => None,
        }
    };
    let mut found = Vec::new();
    for (from, to) in edges.iter().enumerate() {
        if layer_of(from).as_deref() != Some(layer) {
            continue;
        }
        for (target, how) in to {
            if layer_of(*target).is_some_and(|l| forbidden.contains(&l.as_str())) {
                found.push(format!("{} -> {} ({how})", rel(from).display(), rel(*target).display()));
            }
        }
    }
    found
}

#[test]
fn model_uses_no_higher_layer() {
    let found = upward_references("model", &["analysis", "formats", "gpu", "run", "web"]);
    assert!(found.is_empty(), "model/ must not import analysis/, formats/, gpu/, run/ or web/:\n{}", found.join("\n"));
}

#[test]
fn analysis_uses_neither_gpu_nor_run_nor_web() {
    let found = upward_references("analysis", &["formats", "gpu", "run", "web"]);
    assert!(found.is_empty(), "analysis/ must not import formats/, gpu/, run/ or web/:\n{}", found.join("\n"));
}

/// The file formats (run.json, frame files, relaxed states, the code version they record) are
/// bytes of the model's state and parameters, shared by `run` and `web`, the two layers that
/// write and read them: they use the model and nothing else.
#[test]
fn formats_use_only_the_model() {
    let found = upward_references("formats", &["analysis", "gpu", "run", "web"]);
    assert!(found.is_empty(), "formats/ may import only model/:\n{}", found.join("\n"));
}

/// The GPU stages read the model (its parameters, cells and patches) and nothing else: they are
/// a second engine for the same physics, below the layers that would drive them.
#[test]
fn gpu_uses_only_the_model() {
    let found = upward_references("gpu", &["analysis", "formats", "run", "web"]);
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
    assert_eq!(dirs, ["analysis", "formats", "gpu", "model", "run", "web"]);
    let loose: Vec<String> = fs::read_dir(&src)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file())
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .filter(|n| n != "lib.rs" && n != "main.rs")
        .collect();
    assert!(loose.is_empty(), "every module belongs to a layer folder: {loose:?}");
}

/// The check itself must be able to fail: an upward import is found written whole, in a group,
/// and through a re-export of the crate's root; a downward one, a comment and a string are not.
#[test]
fn an_upward_import_is_detected() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path();
    for d in ["model", "run"] {
        fs::create_dir_all(src.join(d)).unwrap();
    }
    fs::write(src.join("lib.rs"), "pub mod model;\npub mod run;\npub use run::Helper;\n").unwrap();
    fs::write(src.join("model/mod.rs"), "mod a;\nmod b;\nmod c;\nmod d;\npub use d::D;\n").unwrap();
    fs::write(src.join("model/a.rs"), "use crate::run::helper::write;\n").unwrap();
    fs::write(src.join("model/b.rs"), "use crate::{model::D, run::Helper as H};\n").unwrap();
    fs::write(src.join("model/c.rs"), "fn f() { let _ = crate::Helper; }\n").unwrap();
    fs::write(
        src.join("model/d.rs"),
        "// use crate::run::Helper; in a comment is fine\npub struct D;\nfn g() -> &'static str { \"crate::run::Helper\" }\n",
    )
    .unwrap();
    fs::write(src.join("run/mod.rs"), "mod helper;\npub use helper::Helper;\n").unwrap();
    fs::write(src.join("run/helper.rs"), "use crate::model::D;\npub struct Helper;\npub fn write() {}\n").unwrap();
    let found = upward_references_in(src, "model", &["run"]);
    assert_eq!(found.len(), 3, "{found:?}");
    for (file, how) in [
        ("model/a.rs", "crate::run::helper::write"),
        ("model/b.rs", "crate::run::Helper"),
        ("model/c.rs", "crate::Helper"),
    ] {
        assert!(found.iter().any(|l| l.starts_with(file) && l.contains(how)), "{file}: {found:?}");
    }
    assert!(upward_references_in(src, "run", &["web"]).is_empty());
}

// ---------------------------------------------------------------------------------------------
// No circles between files: the imports of `src/` (every `use` of `crate::`, `super::`,
// `self::` or a child module, grouped ones included, and every path of `crate::…` or `super::…`
// written in the code) form no loop, however long. A file that imports another which, directly
// or through others, imports it back is two files that can only be read, tested and moved
// together; the shared part belongs in a file below both.

/// A token of Rust source as far as paths need it: a name, `::`, or one punctuation character.
#[derive(Clone, Debug, PartialEq)]
enum Tok {
    Name(String),
    Path,
    Punct(char),
}

/// The tokens of `text` without comments, strings and character literals (so that a path in a
/// doc comment or a message is not an import, and a brace in a string does not count).
fn tokens(text: &str) -> Vec<Tok> {
    let c: Vec<char> = text.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < c.len() {
        let ch = c[i];
        if ch == '/' && c.get(i + 1) == Some(&'/') {
            while i < c.len() && c[i] != '\n' {
                i += 1;
            }
        } else if ch == '/' && c.get(i + 1) == Some(&'*') {
            let mut depth = 0;
            while i < c.len() {
                if c[i] == '/' && c.get(i + 1) == Some(&'*') {
                    depth += 1;
                    i += 2;
                } else if c[i] == '*' && c.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    i += 1;
                }
            }
        } else if ch == 'r' && matches!(c.get(i + 1), Some('"') | Some('#')) && {
            let mut j = i + 1;
            while c.get(j) == Some(&'#') {
                j += 1;
            }
            c.get(j) == Some(&'"')
        } {
            // A raw string r#"…"#: ends at the quote followed by as many hashes.
            let mut j = i + 1;
            let mut hashes = 0;
            while c[j] == '#' {
                hashes += 1;
                j += 1;
            }
            j += 1;
            while j < c.len() && !(c[j] == '"' && (1..=hashes).all(|k| c.get(j + k) == Some(&'#'))) {
                j += 1;
            }
            i = j + 1 + hashes;
        } else if ch == '"' {
            i += 1;
            while i < c.len() && c[i] != '"' {
                i += if c[i] == '\\' { 2 } else { 1 };
            }
            i += 1;
        } else if ch == '\'' {
            // A character literal ('x', '\n', '\u{1F600}'), or else a lifetime ('a).
            if c.get(i + 1) == Some(&'\\') {
                i += 2;
                while i < c.len() && c[i] != '\'' {
                    i += 1;
                }
                i += 1;
            } else if c.get(i + 2) == Some(&'\'') {
                i += 3;
            } else {
                i += 1;
            }
        } else if ch.is_alphanumeric() || ch == '_' {
            let start = i;
            while i < c.len() && (c[i].is_alphanumeric() || c[i] == '_') {
                i += 1;
            }
            out.push(Tok::Name(c[start..i].iter().collect()));
        } else if ch == ':' && c.get(i + 1) == Some(&':') {
            out.push(Tok::Path);
            i += 2;
        } else {
            if !ch.is_whitespace() {
                out.push(Tok::Punct(ch));
            }
            i += 1;
        }
    }
    out
}

/// The paths a `use` tree names, from `toks[*at]` to its `;` (or to the `}`/`,` that ends a
/// group), each prefixed by `prefix`: `a::{b::c, d}` gives `a::b::c` and `a::d`. `self` inside a
/// group names the group's own path; renames (`as x`) keep the path.
fn use_tree(toks: &[Tok], at: &mut usize, prefix: Vec<String>, out: &mut Vec<Vec<String>>) {
    let mut path = prefix;
    while *at < toks.len() {
        match &toks[*at] {
            Tok::Name(n) if n == "as" => {
                *at += 2;
            }
            Tok::Name(n)
                if n == "self" && !path.is_empty() && matches!(toks.get(*at + 1), Some(Tok::Punct(_)) | None) =>
            {
                *at += 1;
            }
            Tok::Name(n) => {
                path.push(n.clone());
                *at += 1;
            }
            Tok::Path => *at += 1,
            Tok::Punct('{') => {
                *at += 1;
                loop {
                    use_tree(toks, at, path.clone(), out);
                    match toks.get(*at) {
                        Some(Tok::Punct(',')) => *at += 1,
                        Some(Tok::Punct('}')) => {
                            *at += 1;
                            break;
                        }
                        _ => break,
                    }
                    if toks.get(*at) == Some(&Tok::Punct('}')) {
                        *at += 1;
                        break;
                    }
                }
                return;
            }
            Tok::Punct('*') => {
                *at += 1;
            }
            Tok::Punct(_) => break,
        }
    }
    out.push(path);
}

/// One file's references to other modules: every `use` path (tagged `true` when it is a
/// `pub use`, a re-export) and every `crate::…`/`super::…` path in the code, each with the module
/// it is written in (the file's, or an inline `mod x { … }` inside it), as written.
struct Refs {
    /// (written in module, path, a `pub use`)
    paths: Vec<(Vec<String>, Vec<String>, bool)>,
}

fn references(text: &str, module: &[String]) -> Refs {
    let toks = tokens(text);
    let mut paths = Vec::new();
    // Inline modules open here: (name, the brace depth inside them).
    let mut inline: Vec<(String, usize)> = Vec::new();
    let mut depth = 0;
    let current = |inline: &[(String, usize)]| {
        let mut m = module.to_vec();
        m.extend(inline.iter().map(|(n, _)| n.clone()));
        m
    };
    let mut i = 0;
    while i < toks.len() {
        match &toks[i] {
            Tok::Punct('{') => depth += 1,
            Tok::Punct('}') => {
                if inline.last().is_some_and(|(_, d)| *d == depth) {
                    inline.pop();
                }
                depth -= 1;
            }
            Tok::Name(m) if m == "mod" => {
                if let (Some(Tok::Name(name)), Some(Tok::Punct('{'))) = (toks.get(i + 1), toks.get(i + 2)) {
                    inline.push((name.clone(), depth + 1));
                    depth += 1;
                    i += 3;
                    continue;
                }
            }
            Tok::Name(u) if u == "use" => {
                let public = i > 0 && toks[i - 1] == Tok::Name("pub".into())
                    || i > 3 && toks[i - 1] == Tok::Punct(')') && toks[i - 4] == Tok::Name("pub".into());
                let mut at = i + 1;
                if toks.get(at) == Some(&Tok::Path) {
                    at += 1;
                }
                let mut found = Vec::new();
                use_tree(&toks, &mut at, Vec::new(), &mut found);
                let here = current(&inline);
                paths.extend(found.into_iter().map(|p| (here.clone(), p, public)));
                i = at;
                continue;
            }
            Tok::Name(start)
                if (start == "crate" || start == "super")
                    && toks.get(i + 1) == Some(&Tok::Path)
                    && (i == 0 || toks[i - 1] != Tok::Path) =>
            {
                let mut path = vec![start.clone()];
                let mut at = i + 1;
                while toks.get(at) == Some(&Tok::Path) {
                    match toks.get(at + 1) {
                        Some(Tok::Name(n)) => path.push(n.clone()),
                        _ => break,
                    }
                    at += 2;
                }
                paths.push((current(&inline), path, false));
                i = at;
                continue;
            }
            _ => {}
        }
        i += 1;
    }
    Refs { paths }
}

/// The module path of a file of `src/` (`model/monolayer.rs` → `model::monolayer`, `web/mod.rs`
/// → `web`, `lib.rs` → the crate).
fn module_of(src: &Path, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(src).unwrap().with_extension("");
    let mut m: Vec<String> = rel.iter().map(|s| s.to_string_lossy().into_owned()).collect();
    if matches!(m.last().map(String::as_str), Some("mod") | Some("lib") | Some("main")) {
        m.pop();
    }
    m
}

/// The files of `src` and, for each, the files it imports (resolved through re-exports:
/// `crate::gpu::GpuContext` is `gpu/context.rs`, not `gpu/mod.rs` that re-exports it).
fn import_graph(src: &Path) -> (Vec<PathBuf>, Vec<Vec<(usize, String)>>) {
    let files = rust_files(src);
    let modules: Vec<Vec<String>> = files.iter().map(|f| module_of(src, f)).collect();
    let refs: Vec<Refs> =
        files.iter().zip(&modules).map(|(f, m)| references(&fs::read_to_string(f).unwrap(), m)).collect();
    let is_main = |i: usize| files[i].file_name().is_some_and(|n| n == "main.rs");
    // A path as written in module `here` of file `from`, made absolute (None: another crate).
    let absolute = |from: usize, here: &[String], path: &[String]| -> Option<Vec<String>> {
        let first = path.first()?;
        let mut base: Vec<String> = here.to_vec();
        let mut rest = path;
        match first.as_str() {
            "crate" => {
                base.clear();
                rest = &path[1..];
            }
            "monolayer" if is_main(from) => {
                base.clear();
                rest = &path[1..];
            }
            "self" => rest = &path[1..],
            "super" => {
                while rest.first().is_some_and(|s| s == "super") {
                    base.pop();
                    rest = &rest[1..];
                }
            }
            _ => {
                // A child module of this one (`use buffers::Slot;` in gpu/mod.rs), else a crate.
                let mut child = base.clone();
                child.push(first.clone());
                if is_main(from) || !modules.contains(&child) {
                    return None;
                }
            }
        }
        base.extend(rest.iter().cloned());
        Some(base)
    };
    // The file a path leads to: the longest module prefix, then through that module's `pub use`.
    fn resolve(
        path: Vec<String>,
        modules: &[Vec<String>],
        exports: &[Vec<(String, Vec<String>)>],
        hops: usize,
    ) -> Option<usize> {
        let (file, len) = (0..=path.len())
            .rev()
            .find_map(|k| modules.iter().position(|m| m.as_slice() == &path[..k]).map(|f| (f, k)))?;
        if len < path.len() && hops < 8 {
            if let Some((_, target)) = exports[file].iter().find(|(name, _)| *name == path[len]) {
                let mut next = target.clone();
                next.extend(path[len + 1..].iter().cloned());
                return resolve(next, modules, exports, hops + 1).or(Some(file));
            }
        }
        Some(file)
    }
    // Each module's re-exports: the name it exports → the absolute path it stands for.
    let exports: Vec<Vec<(String, Vec<String>)>> = (0..files.len())
        .map(|f| {
            refs[f]
                .paths
                .iter()
                .filter(|(_, _, public)| *public)
                .filter_map(|(here, p, _)| Some((p.last()?.clone(), absolute(f, here, p)?)))
                .collect()
        })
        .collect();
    let edges = (0..files.len())
        .map(|f| {
            let mut to: Vec<(usize, String)> = refs[f]
                .paths
                .iter()
                .filter_map(|(here, p, _)| {
                    let target = resolve(absolute(f, here, p)?, &modules, &exports, 0)?;
                    (target != f).then(|| (target, p.join("::")))
                })
                .collect();
            to.sort();
            to.dedup_by_key(|(t, _)| *t);
            to
        })
        .collect();
    (files, edges)
}

/// Every circle of the import graph of `src`, each as its files in order with what ties them.
fn import_circles(src: &Path) -> Vec<String> {
    let (files, edges) = import_graph(src);
    let n = files.len();
    // Tarjan's strongly connected components: a component of two or more files is a circle.
    struct T<'a> {
        edges: &'a [Vec<(usize, String)>],
        index: Vec<Option<usize>>,
        low: Vec<usize>,
        on: Vec<bool>,
        stack: Vec<usize>,
        next: usize,
        found: Vec<Vec<usize>>,
    }
    fn visit(t: &mut T, v: usize) {
        t.index[v] = Some(t.next);
        t.low[v] = t.next;
        t.next += 1;
        t.stack.push(v);
        t.on[v] = true;
        for &(w, _) in &t.edges[v] {
            match t.index[w] {
                None => {
                    visit(t, w);
                    t.low[v] = t.low[v].min(t.low[w]);
                }
                Some(iw) if t.on[w] => t.low[v] = t.low[v].min(iw),
                _ => {}
            }
        }
        if Some(t.low[v]) == t.index[v] {
            let mut part = Vec::new();
            loop {
                let w = t.stack.pop().unwrap();
                t.on[w] = false;
                part.push(w);
                if w == v {
                    break;
                }
            }
            if part.len() > 1 {
                part.sort();
                t.found.push(part);
            }
        }
    }
    let mut t = T {
        edges: &edges,
        index: vec![None; n],
        low: vec![0; n],
        on: vec![false; n],
        stack: Vec::new(),
        next: 0,
        found: Vec::new(),
    };
    for v in 0..n {
        if t.index[v].is_none() {
            visit(&mut t, v);
        }
    }
    let name = |f: usize| files[f].strip_prefix(src).unwrap().display().to_string();
    t.found
        .iter()
        .map(|part| {
            let ties: Vec<String> = part
                .iter()
                .flat_map(|&a| {
                    edges[a]
                        .iter()
                        .filter(|(b, _)| part.contains(b))
                        .map(move |(b, how)| format!("  {} -> {} ({how})", name(a), name(*b)))
                })
                .collect();
            format!("{}:\n{}", part.iter().map(|&f| name(f)).collect::<Vec<_>>().join(", "), ties.join("\n"))
        })
        .collect()
}

#[test]
fn no_files_import_each_other_around_a_circle() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let circles = import_circles(&src);
    assert!(
        circles.is_empty(),
        "files of src/ that import each other (move what they share into a file below them):\n{}",
        circles.join("\n")
    );
}

/// The check itself must be able to fail: a loop through a grouped import, a `super::` path and
/// a path written in an expression is found; imports of one direction, comments, strings and a
/// test module's `use super::*` are not circles.
#[test]
fn a_circle_of_imports_is_detected() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path();
    fs::create_dir_all(src.join("a")).unwrap();
    fs::create_dir_all(src.join("b")).unwrap();
    fs::write(src.join("lib.rs"), "pub mod a;\npub mod b;\npub use a::x::X;\n").unwrap();
    fs::write(src.join("a/mod.rs"), "pub mod x;\npub mod y;\npub use x::X;\n").unwrap();
    fs::write(
        src.join("a/x.rs"),
        "use crate::{b::{self, z::Z}, a::y as why};\n// use crate::b::w; in a comment\npub struct X;\n\
         #[cfg(test)]\nmod tests {\n    use super::*;\n}\n",
    )
    .unwrap();
    fs::write(src.join("a/y.rs"), "pub fn f() -> u8 { let s = \"crate::b::w\"; s.len() as u8 }\n").unwrap();
    fs::write(src.join("b/mod.rs"), "pub mod w;\npub mod z;\n").unwrap();
    fs::write(src.join("b/z.rs"), "pub struct Z;\npub fn g() { super::w::h() }\n").unwrap();
    fs::write(src.join("b/w.rs"), "pub fn h() { let _ = crate::X; }\n").unwrap();
    let circles = import_circles(src);
    assert_eq!(circles.len(), 1, "{circles:?}");
    assert!(circles[0].starts_with("a/x.rs, b/w.rs, b/z.rs:"), "{circles:?}");
    assert!(circles[0].contains("b/w.rs -> a/x.rs (crate::X)"), "through the crate's re-export: {circles:?}");
    // Without the expression's path back, no circle.
    fs::write(src.join("b/w.rs"), "pub fn h() {}\n").unwrap();
    assert!(import_circles(src).is_empty(), "{:?}", import_circles(src));
    // Two files importing each other directly.
    fs::write(src.join("b/w.rs"), "use super::z::Z;\n").unwrap();
    assert_eq!(import_circles(src).len(), 1, "{:?}", import_circles(src));
}

/// The `use` lines of `text` that take an item from the crate's root (`crate::Monolayer`, the
/// re-exports for the library's users) instead of from its layer (`crate::model::Monolayer`).
fn root_imports(text: &str) -> Vec<String> {
    const LAYERS: [&str; 6] = ["model", "analysis", "formats", "gpu", "run", "web"];
    text.lines()
        .map(str::trim)
        .filter(|l| l.starts_with("use crate::") || l.starts_with("pub use crate::"))
        .filter(|l| {
            let rest = l.split("crate::").nth(1).unwrap_or("");
            !LAYERS
                .iter()
                .any(|layer| rest.starts_with(&format!("{layer}::")) || rest.starts_with(&format!("{layer};")))
        })
        .map(String::from)
        .collect()
}

/// One import style inside the crate: every item from its layer, so that a reader sees where it
/// lives (the crate's root re-exports a few core types for the library's users only).
#[test]
fn the_crate_imports_from_layers_not_its_root() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let found: Vec<String> = rust_files(&src)
        .into_iter()
        .flat_map(|f| {
            let text = fs::read_to_string(&f).unwrap();
            root_imports(&text).into_iter().map(move |l| format!("{}: {l}", f.display()))
        })
        .collect();
    assert!(found.is_empty(), "imports from the crate's root (take them from their layer):\n{}", found.join("\n"));
}

#[test]
fn an_import_from_the_root_is_detected() {
    assert_eq!(
        root_imports("use crate::{Monolayer, Params};\nuse crate::model::Patch;"),
        ["use crate::{Monolayer, Params};"]
    );
    assert!(root_imports("    use crate::model::{Monolayer, Params};\nuse crate::run::RunDir;").is_empty());
}
