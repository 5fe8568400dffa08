//! `run.json` has one type (`formats::run_record::RunRecord`) and two writers: `monolayer run`
//! (`run::files`) and the page's download (`web::readouts::run_record_json`). The bytes each
//! writes are those it wrote before the type was shared (tests/data/run_record_*.json, with the
//! version as `VERSION`): the same keys, values and order for every reader. Both record the same
//! version: the crate's and the commit's (`formats::version::code_version`).

mod common;

use std::fs;

use common::{quick_run, stderr};
use monolayer::formats::{code_version, RunRecord, RunStatus};
use monolayer::web::run_record_json;
use monolayer::{Monolayer, Params};

fn expected(name: &str) -> String {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data").join(name);
    let text = fs::read_to_string(&path).unwrap();
    assert_eq!(text.matches("\"version\": \"VERSION\"").count(), 1, "{name}");
    text.replace("\"version\": \"VERSION\"", &format!("\"version\": \"{}\"", code_version()))
}

fn params() -> Params {
    Params { box_size: 40, n_cells: 6, relax_steps: 60, ..Params::default() }
}

fn version_of(json: &str) -> String {
    let v: serde_json::Value = serde_json::from_str(json).unwrap();
    v["version"].as_str().expect("a version").to_string()
}

#[test]
fn the_native_writer_writes_the_bytes_it_always_wrote() {
    let dir = tempfile::tempdir().unwrap();
    let mut r = RunRecord::new(params(), 3, 10);
    r.save(dir.path()).unwrap();
    assert_eq!(fs::read_to_string(dir.path().join("run.json")).unwrap(), expected("run_record_native.json"));
    r.status = RunStatus::Finished;
    r.last_frame_step = Some(70);
    r.engine = "gpu-f32".into();
    r.save(dir.path()).unwrap();
    let written = fs::read_to_string(dir.path().join("run.json")).unwrap();
    assert_eq!(written, expected("run_record_native_finished.json"));
    let back = RunRecord::load(dir.path()).unwrap();
    assert_eq!((back.status, back.last_frame_step, back.engine.as_str()), (RunStatus::Finished, Some(70), "gpu-f32"));
}

#[test]
fn the_pages_writer_writes_the_bytes_it_always_wrote() {
    let mut m = Monolayer::new(params(), 3).unwrap();
    m.advance(5).unwrap();
    let json = run_record_json(&m);
    assert_eq!(json, expected("run_record_page.json"));
    // Read back by the native reader as a run of one frame on the CPU engine (no engine named).
    let dir = tempfile::tempdir().unwrap();
    fs::write(dir.path().join("run.json"), &json).unwrap();
    let r = RunRecord::load(dir.path()).unwrap();
    assert_eq!((r.seed, r.frame_interval, r.last_frame_step, r.engine.as_str()), (3, 1, Some(5), "cpu"));
    assert_eq!(r.status, RunStatus::Stopped("the state of the browser page, downloaded".into()));
    assert_eq!(&r.params, m.params());
}

/// `monolayer run` and the page record the same version: the crate's with the commit.
#[test]
fn both_writers_record_the_same_version_with_the_commit() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let o = quick_run(&run, 40, 6, "10", "10", &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let native = version_of(&fs::read_to_string(run.join("run.json")).unwrap());
    let page = version_of(&run_record_json(&Monolayer::new(params(), 1).unwrap()));
    assert_eq!(native, page);
    assert_eq!(native, code_version());
    let (crate_version, commit) = native.split_once('+').expect("version+commit");
    assert_eq!(crate_version, env!("CARGO_PKG_VERSION"));
    assert!(!commit.is_empty());
    assert_eq!(native, monolayer::web::code_version(), "the page's codeVersion");
}
