//! The page's frame files (`formats::frame_file`, the code the browser runs, here natively) against
//! the native ones: frames written by `monolayer run` decode to the same arrays as
//! `monolayer analyze` reads, the page's own frame of a state is the native frame of it byte for
//! byte, and the page's download (frame + run.json) is a run `monolayer analyze` accepts.

mod common;

use std::fs;

use common::{arg, monolayer, quick_run, stderr};
use monolayer::formats::{decode_frame, encode_frame, frame_file_name, RunRecord};
use monolayer::run::{read_frame, write_frame, RunFrames};
use monolayer::web::run_record_json;
use monolayer::{Monolayer, Params};

#[test]
fn frames_written_by_monolayer_run_decode_to_the_arrays_analyze_reads() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let o = quick_run(&run, 40, 6, "60", "20", &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let frames = RunFrames::open(&run).unwrap();
    assert_eq!(frames.frames.len(), 3, "frames at the end of relaxation and every 10 steps");
    let p = &frames.record.params;
    for (step, path) in &frames.frames {
        let native = read_frame(path, p.box_size).unwrap();
        let name = path.file_name().unwrap().to_string_lossy();
        let page = decode_frame(&name, &fs::read(path).unwrap(), Some((p.box_size, p.n_cells))).unwrap();
        assert_eq!((page.step, page.l), (*step, p.box_size));
        assert_eq!(page, native.data, "{name}: the page and analyze read the same frame");
    }
    // A damaged frame: refused with its name and the reason, as analyze refuses it.
    let (_, path) = &frames.frames[1];
    let bytes = fs::read(path).unwrap();
    let e = decode_frame("frame_0000070.npz", &bytes[..bytes.len() - 100], None).unwrap_err().to_string();
    assert!(e.starts_with("frame_0000070.npz: not a readable .npz"), "{e}");
}

#[test]
fn the_pages_frame_is_the_native_frame_and_its_download_is_a_run_analyze_reads() {
    let p = Params { box_size: 40, n_cells: 6, relax_steps: 60, ..Params::default() };
    let mut m = Monolayer::new(p, 3).unwrap();
    m.advance(75).unwrap();
    let bytes = encode_frame(&mut m).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let native = dir.path().join("native.npz");
    write_frame(&mut m, &native).unwrap();
    assert!(fs::read(&native).unwrap() == bytes, "the page's frame differs from the native frame of the same state");

    // The download, laid out as docs/demo.md ("Data out") says: run.json and frames/frame_<step>.npz.
    let run = dir.path().join("downloaded");
    fs::create_dir_all(run.join("frames")).unwrap();
    fs::write(run.join("run.json"), run_record_json(&m)).unwrap();
    fs::write(run.join("frames").join(frame_file_name(m.step_count())), &bytes).unwrap();
    let record = RunRecord::load(&run).unwrap();
    assert_eq!((record.seed, &record.params), (3, m.params()));
    let out = dir.path().join("analysis");
    let o = monolayer(&["analyze", arg(&run), "--out", arg(&out)]);
    assert!(o.status.success(), "analyze refused the page's download: {}", stderr(&o));
    assert!(fs::read_dir(&out).unwrap().count() > 0, "analyze wrote nothing");
}

/// The page opens a full-size frame (100 cells on 140×140, the paper's size) of `monolayer run`
/// as it opens a small one: the same code as in the browser, here natively.
#[test]
fn a_full_size_frame_opens_in_the_pages_playback() {
    use monolayer::web::{FieldKind, Playback};
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let o = monolayer(&[
        "run",
        "--quiet",
        "--relax-steps",
        "10",
        "--steps",
        "10",
        "--frame-interval",
        "10",
        "--threads",
        "1",
        "--out",
        arg(&run),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let frames = RunFrames::open(&run).unwrap();
    assert_eq!((frames.record.params.box_size, frames.record.params.n_cells), (140, 100), "the paper's size");
    let json = fs::read_to_string(run.join("run.json")).unwrap();
    let mut play = Playback::new(Some(("run.json", &json))).unwrap();
    for (step, path) in &frames.frames {
        let name = path.file_name().unwrap().to_string_lossy();
        let bytes = fs::read(path).unwrap();
        assert_eq!(play.check(&name, &bytes), Ok(*step));
        play.show(&name, &bytes).unwrap();
        let view = play.view(FieldKind::StrainRate, 1.0).unwrap();
        assert_eq!((view.l, view.tissue.len()), (140, 140 * 140));
    }
}
