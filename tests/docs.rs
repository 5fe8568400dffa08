//! The documentation's links hold: in README.md, CONTRIBUTING.md, CHANGELOG.md and every
//! Markdown file under docs/ (the generated reports of docs/evidence/ too), every relative link
//! leads to a file or folder of the repository, and every `#anchor` into a Markdown file names
//! one of its headings (as GitHub makes them: lower case, punctuation other than `-` and `_`
//! dropped, spaces as `-`, a repeated heading numbered `-1`, `-2`, …). Links to the web
//! (`https:`, `mailto:`, …) are not followed. Every file of docs/evidence/ is listed in its
//! README.md with the build that made it.

use std::collections::BTreeSet;
use std::fs;
use std::path::{Path, PathBuf};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The Markdown files checked: the three at the top and every one under docs/.
fn documents(root: &Path) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> =
        ["README.md", "CONTRIBUTING.md", "CHANGELOG.md"].iter().map(|n| root.join(n)).filter(|p| p.exists()).collect();
    let mut docs: Vec<PathBuf> =
        files_under(&root.join("docs")).into_iter().filter(|p| p.extension().is_some_and(|x| x == "md")).collect();
    docs.sort();
    out.extend(docs);
    out
}

/// Every file under `dir`, at any depth.
fn files_under(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in fs::read_dir(dir).into_iter().flatten().flatten() {
        let path = e.path();
        if path.is_dir() {
            out.extend(files_under(&path));
        } else {
            out.push(path);
        }
    }
    out
}

/// Every file of docs/evidence/ is listed in its README.md, in a row that names the build (a git
/// commit) that made it.
#[test]
fn every_evidence_file_is_listed_with_its_build() {
    let evidence = root().join("docs/evidence");
    let readme = fs::read_to_string(evidence.join("README.md")).unwrap();
    let mut missing = Vec::new();
    for file in files_under(&evidence) {
        let name = file.strip_prefix(&evidence).unwrap().display().to_string();
        if name == "README.md" {
            continue;
        }
        let row = readme.lines().find(|l| l.starts_with('|') && l.contains(&format!("]({name})")));
        let built = row.is_some_and(|r| {
            r.split('`').skip(1).step_by(2).any(|code| code.len() >= 7 && code.chars().all(|c| c.is_ascii_hexdigit()))
        });
        if !built {
            missing.push(name);
        }
    }
    assert!(missing.is_empty(), "not listed with a build in docs/evidence/README.md: {missing:?}");
}

/// The lines of `text` outside fenced code blocks (``` or ~~~), with their numbers, and inline
/// code spans blanked: neither holds links.
fn prose_lines(text: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    let mut fence: Option<&str> = None;
    for (i, line) in text.lines().enumerate() {
        let t = line.trim_start();
        let opens = ["```", "~~~"].into_iter().find(|f| t.starts_with(f));
        match (fence, opens) {
            (None, Some(f)) => fence = Some(f),
            (Some(f), Some(g)) if f == g => fence = None,
            (None, None) => out.push((i + 1, without_code_spans(line))),
            _ => {}
        }
    }
    out
}

fn without_code_spans(line: &str) -> String {
    let mut out = String::new();
    let mut code = false;
    for c in line.chars() {
        if c == '`' {
            code = !code;
            out.push('`');
        } else if !code {
            out.push(c);
        }
    }
    out
}

/// The targets of a line's links: inline `[text](target "title")` and `![alt](target)`, and
/// reference definitions `[name]: target`.
fn link_targets(line: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = line;
    while let Some(at) = rest.find("](") {
        let after = &rest[at + 2..];
        let mut depth = 1;
        let mut end = None;
        for (i, c) in after.char_indices() {
            match c {
                '(' => depth += 1,
                ')' => {
                    depth -= 1;
                    if depth == 0 {
                        end = Some(i);
                        break;
                    }
                }
                _ => {}
            }
        }
        let Some(end) = end else { break };
        let target = after[..end].trim();
        let target = target.trim_start_matches('<').split(['>', ' ']).next().unwrap_or("");
        out.push(target.to_string());
        rest = &after[end..];
    }
    let t = line.trim_start();
    if t.starts_with('[') && !t.starts_with("[^") {
        if let Some(close) = t.find("]:") {
            if let Some(target) = t[close + 2..].split_whitespace().next() {
                out.push(target.trim_matches(['<', '>']).to_string());
            }
        }
    }
    out
}

/// GitHub's anchor of a heading's text: links reduced to their text, lower case, characters
/// other than letters, digits, spaces, `-` and `_` dropped, spaces as `-`.
fn slug(heading: &str) -> String {
    let mut text = String::new();
    let mut rest = heading;
    // [text](url) → text
    while let Some(open) = rest.find('[') {
        match (rest[open..].find("]("), rest[open..].find(')')) {
            (Some(mid), Some(close)) if mid < close => {
                text.push_str(&rest[..open]);
                text.push_str(&rest[open + 1..open + mid]);
                rest = &rest[open + close + 1..];
            }
            _ => {
                text.push_str(&rest[..=open]);
                rest = &rest[open + 1..];
            }
        }
    }
    text.push_str(rest);
    text.trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || *c == ' ' || *c == '-' || *c == '_')
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// The anchors of a Markdown file: its headings' (numbered when repeated) and any HTML
/// `id="…"`/`name="…"`.
fn anchors(text: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let mut seen: std::collections::HashMap<String, usize> = Default::default();
    let mut fence: Option<&str> = None;
    for line in text.lines() {
        let t = line.trim_start();
        if let Some(f) = ["```", "~~~"].into_iter().find(|f| t.starts_with(f)) {
            fence = match fence {
                None => Some(f),
                Some(g) if g == f => None,
                other => other,
            };
            continue;
        }
        if fence.is_some() {
            continue;
        }
        let hashes = t.chars().take_while(|c| *c == '#').count();
        if (1..=6).contains(&hashes) && t[hashes..].starts_with([' ', '\t']) {
            let heading = t[hashes..].trim().trim_end_matches('#').trim();
            let base = slug(heading);
            let n = seen.entry(base.clone()).or_insert(0);
            out.insert(if *n == 0 { base.clone() } else { format!("{base}-{n}") });
            *n += 1;
        }
        for attr in ["id=\"", "name=\""] {
            let mut rest = line;
            while let Some(at) = rest.find(attr) {
                let value = &rest[at + attr.len()..];
                let end = value.find('"').unwrap_or(value.len());
                out.insert(value[..end].to_string());
                rest = &value[end..];
            }
        }
    }
    out
}

/// Every broken link of the documents, as `file:line: target: why`.
fn broken_links(root: &Path, docs: &[PathBuf]) -> Vec<String> {
    let mut broken = Vec::new();
    for doc in docs {
        let text = fs::read_to_string(doc).unwrap();
        let name = doc.strip_prefix(root).unwrap_or(doc).display().to_string();
        for (n, line) in prose_lines(&text) {
            for target in link_targets(&line) {
                if target.is_empty() || target.contains("://") || target.starts_with("mailto:") {
                    continue;
                }
                let (path, anchor) = match target.split_once('#') {
                    Some((p, a)) => (p, Some(a)),
                    None => (target.as_str(), None),
                };
                let file = if path.is_empty() { doc.clone() } else { doc.parent().unwrap().join(path) };
                if !file.exists() {
                    broken.push(format!("{name}:{n}: {target}: no such file"));
                    continue;
                }
                let Some(anchor) = anchor else { continue };
                if file.extension().is_none_or(|x| x != "md") {
                    continue;
                }
                let there = anchors(&fs::read_to_string(&file).unwrap());
                if !there.contains(anchor) {
                    broken.push(format!("{name}:{n}: {target}: no heading with the anchor #{anchor}"));
                }
            }
        }
    }
    broken
}

#[test]
fn every_relative_link_of_the_docs_resolves() {
    let docs = documents(root());
    assert!(docs.len() > 3, "{docs:?}");
    let broken = broken_links(root(), &docs);
    assert!(broken.is_empty(), "{} broken links:\n{}", broken.len(), broken.join("\n"));
}

/// GitHub's rule, on headings of the kind the docs have.
#[test]
fn anchors_are_githubs() {
    assert_eq!(slug("Data out"), "data-out");
    assert_eq!(slug("The page's `run.json` (and frames)"), "the-pages-runjson-and-frames");
    assert_eq!(slug("ζ, χ and γ: the sliders"), "ζ-χ-and-γ-the-sliders");
    assert_eq!(slug("snake_case and kebab-case"), "snake_case-and-kebab-case");
    assert_eq!(slug("See [demo.md](demo.md) first"), "see-demomd-first");
    let a = anchors("# Top\n## Notes\n```\n# not a heading\n```\n## Notes\n<a id=\"here\"></a>\n");
    assert_eq!(a.into_iter().collect::<Vec<_>>(), ["here", "notes", "notes-1", "top"]);
}

/// The check itself must be able to fail: a missing file and a missing anchor are found; links
/// in code, to the web and to existing headings are not.
#[test]
fn a_broken_link_is_detected() {
    let dir = tempfile::tempdir().unwrap();
    let docs = dir.path().join("docs");
    fs::create_dir(&docs).unwrap();
    fs::write(docs.join("b.md"), "# B\n\n## Shipped states\n").unwrap();
    fs::write(
        dir.path().join("README.md"),
        "# A\nSee [b](docs/b.md#shipped-states), [web](https://example.org/x.md#y), [top](#a).\n\
         `[code](nowhere.md)`\n```\n[fenced](nowhere.md)\n```\n\
         [gone](docs/c.md) and [moved](docs/b.md#shipped-state)\n[ref]: docs/d.md\n",
    )
    .unwrap();
    let broken = broken_links(dir.path(), &[dir.path().join("README.md"), docs.join("b.md")]);
    assert_eq!(
        broken,
        [
            "README.md:7: docs/c.md: no such file",
            "README.md:7: docs/b.md#shipped-state: no heading with the anchor #shipped-state",
            "README.md:8: docs/d.md: no such file",
        ],
        "{broken:?}"
    );
}

/// CONTRIBUTING.md's code map names every source file: each `src/**/NAME.rs` by NAME (a `mod.rs`
/// by its folder), as a word of the map.
#[test]
fn the_code_map_names_every_source_file() {
    let text = fs::read_to_string(root().join("CONTRIBUTING.md")).unwrap();
    let start = text.find("## Code map").expect("a code map");
    let end = text[start..].find("\n## ").map_or(text.len(), |e| start + e + 1);
    let map = &text[start..end];
    let is_word = |c: char| c.is_alphanumeric() || c == '_' || c == '-';
    let named = |name: &str| {
        map.match_indices(name).any(|(at, _)| {
            !map[..at].chars().next_back().is_some_and(is_word)
                && !map[at + name.len()..].chars().next().is_some_and(is_word)
        })
    };
    let mut missing: Vec<String> = files_under(&root().join("src"))
        .into_iter()
        .filter(|p| p.extension().is_some_and(|x| x == "rs"))
        .filter_map(|p| {
            let stem = p.file_stem()?.to_string_lossy().into_owned();
            let name = if stem == "mod" { p.parent()?.file_name()?.to_string_lossy().into_owned() } else { stem };
            (!named(&name)).then(|| p.strip_prefix(root()).unwrap().display().to_string())
        })
        .collect();
    missing.sort();
    assert!(missing.is_empty(), "CONTRIBUTING.md's code map does not name: {missing:?}");
}
