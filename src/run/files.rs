//! A run's files: frames NumPy reads directly (`.npz`), bit-exact checkpoints, and the run record
//! (`run.json`), with the writer and the reader of each side by side. The formats themselves,
//! which the page writes and reads too, are `crate::formats`'s (the frame codec, the record's
//! type, the frame file's name); this module adds the files. Every file is written to a
//! temporary name in the same directory and renamed, so a reader (or a crash) never sees half a
//! file; every read error names the file and the array that is wrong.

use std::fs::{self, File};
use std::io::{BufReader, BufWriter, Cursor, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use ndarray::{arr0, Array1, Array2, Array3};
use ndarray_npy::{NpzReader, NpzWriter};
use num_complex::Complex64 as C64;

use crate::formats::{self, frame_file_name, Engine, FrameData, RunRecord, FORMAT, FORMAT_VERSION};
use crate::model::{Monolayer, Params, Patch, State, MAX_BOX_SIZE};
use crate::run::error::RunError;

pub type IoResult<T> = Result<T, RunError>;

fn err(path: &Path, e: impl std::fmt::Display) -> RunError {
    RunError::file(path, e)
}

fn io(path: &Path, e: std::io::Error) -> RunError {
    RunError::io(path, e)
}

/// The exact state a run continues from (`--resume`), in the run's directory.
pub const CHECKPOINT: &str = "checkpoint.npz";
/// The state before the step that made a run unstable.
pub const LAST_GOOD_STATE: &str = "last_good_state.npz";

/// Where the checkpoint of the run in `dir` is: `dir/checkpoint.npz`.
pub fn checkpoint_path(dir: &Path) -> PathBuf {
    dir.join(CHECKPOINT)
}

/// The folder of a run's kept checkpoints (`RunRecord::keep_checkpoints`).
pub const KEPT_CHECKPOINTS: &str = "checkpoints";

/// Where a run that keeps its checkpoints keeps the one of `step`:
/// `dir/checkpoints/checkpoint_0011000.npz`.
pub fn kept_checkpoint_path(dir: &Path, step: u64) -> PathBuf {
    dir.join(KEPT_CHECKPOINTS).join(format!("checkpoint_{step:07}.npz"))
}

/// Keeps the checkpoint just written at `dir/checkpoint.npz` as the one of `step`: a hard link
/// (no second write of the same bytes), or a copy where the file system has none, renamed into
/// place whole either way.
pub fn keep_checkpoint(dir: &Path, step: u64) -> IoResult<()> {
    let from = checkpoint_path(dir);
    let to = kept_checkpoint_path(dir, step);
    let folder = dir.join(KEPT_CHECKPOINTS);
    fs::create_dir_all(&folder).map_err(|e| io(&folder, e))?;
    let tmp = folder.join(format!(".checkpoint_{step:07}.npz.{}.link.tmp", std::process::id()));
    let _ = fs::remove_file(&tmp);
    if fs::hard_link(&from, &tmp).is_err() {
        fs::copy(&from, &tmp).map_err(|e| io(&tmp, e))?;
    }
    fs::rename(&tmp, &to).map_err(|e| {
        let _ = fs::remove_file(&tmp);
        io(&to, e)
    })
}

/// Writes `path` through a temporary file in the same directory and a rename. The temporary
/// name is this process's and this call's own, so that two writers of one file (`analyze`
/// beside `run --analyze`) never rename each other's half-written files.
pub fn write_atomic(path: &Path, write: impl FnOnce(&mut BufWriter<File>) -> IoResult<()>) -> IoResult<()> {
    static CALLS: AtomicU64 = AtomicU64::new(0);
    let path = &replaceable(path)?;
    let dir = path.parent().unwrap_or(Path::new("."));
    let name = path.file_name().ok_or_else(|| err(path, "not a file name"))?.to_string_lossy();
    let call = CALLS.fetch_add(1, Ordering::Relaxed);
    let tmp = dir.join(temporary_name(&name, call));
    let file = File::create(&tmp).map_err(|e| io(&tmp, e))?;
    let mut w = BufWriter::new(file);
    let result = write(&mut w).and_then(|_| {
        let file = w.into_inner().map_err(|e| io(&tmp, e.into_error()))?;
        file.sync_all().map_err(|e| io(&tmp, e))
    });
    if let Err(e) = result {
        let _ = fs::remove_file(&tmp);
        return Err(e);
    }
    fs::rename(&tmp, path).map_err(|e| {
        let _ = fs::remove_file(&tmp);
        io(path, e)
    })
}

/// The most bytes of a file name (Linux's NAME_MAX, and most file systems').
const NAME_MAX: usize = 255;

/// The temporary name [`write_atomic`] writes `name` under: `.NAME.PID.CALL.tmp`, this process's
/// and this call's own, with `NAME` shortened (at a character boundary) where the whole would
/// exceed [`NAME_MAX`]: an output name near the limit is written, not refused on its temporary.
fn temporary_name(name: &str, call: u64) -> String {
    let suffix = format!(".{}.{call}.tmp", std::process::id());
    let mut room = NAME_MAX - 1 - suffix.len();
    while room < name.len() && !name.is_char_boundary(room) {
        room -= 1;
    }
    format!(".{}{suffix}", &name[..room.min(name.len())])
}

/// Writes `text` to `path` atomically ([`write_atomic`]): the tables, reports and scripts.
pub fn write_text(path: &Path, text: &str) -> IoResult<()> {
    write_atomic(path, |w| w.write_all(text.as_bytes()).map_err(|e| io(path, e)))
}

/// The file a rename into `path` replaces: `path` itself, or the regular file a symbolic link
/// there points to (so that the link is written through, not replaced). A rename replaces
/// whatever is at its target, so anything else (a device such as `/dev/null`, a FIFO, a
/// directory, a link to one of those or to nothing) is refused before a byte is written.
pub fn replaceable(path: &Path) -> IoResult<PathBuf> {
    check_output_name(path)?;
    let link = match fs::symlink_metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(path.to_path_buf()),
        Err(e) => return Err(io(path, e)),
        Ok(m) => m.file_type().is_symlink(),
    };
    let target = match fs::metadata(path) {
        Ok(m) => m,
        Err(e) if link => {
            return Err(err(path, format!("a symbolic link to nothing readable ({e}): refused as an output file")))
        }
        Err(e) => return Err(io(path, e)),
    };
    if !target.is_file() {
        let kind = file_kind(&target.file_type());
        let via = if link { "a symbolic link to " } else { "" };
        return Err(err(
            path,
            format!(
                "exists and is {via}{kind}, not a regular file: it would be replaced by this output; give the path \
                 of a regular file or of none"
            ),
        ));
    }
    if link {
        return fs::canonicalize(path).map_err(|e| io(path, e));
    }
    Ok(path.to_path_buf())
}

/// Checks what an output path's name and directory allow before anything is computed for it:
/// a name of at most [`NAME_MAX`] bytes in a directory that exists (else the write would fail
/// only at the end, naming its temporary file).
fn check_output_name(path: &Path) -> IoResult<()> {
    let name = path.file_name().ok_or_else(|| err(path, "not a file name: give the path of a file"))?;
    if name.len() > NAME_MAX {
        return Err(err(
            path,
            format!("a file name of {} bytes: longer than the {NAME_MAX} a file name may have", name.len()),
        ));
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    match fs::metadata(dir) {
        Ok(m) if m.is_dir() => Ok(()),
        Ok(_) => Err(err(dir, format!("not a directory, so {} cannot be written in it", path.display()))),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Err(err(
            dir,
            format!("no such directory, so {} cannot be written: create it first, or write elsewhere", path.display()),
        )),
        Err(e) => Err(io(dir, e)),
    }
}

fn file_kind(t: &fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return "a FIFO";
        }
        if t.is_char_device() {
            return "a character device";
        }
        if t.is_block_device() {
            return "a block device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    if t.is_dir() {
        "a directory"
    } else {
        "not a regular file"
    }
}

/// Checks, before anything is computed, that `out` (given as `flag`) can be the directory of a
/// set of outputs: a directory, or nothing yet (it is created). A file there would fail only at
/// the end, on the name of a temporary.
pub fn check_output_dir(flag: &str, out: &Path) -> IoResult<()> {
    match fs::metadata(out) {
        Ok(m) if m.is_dir() => Ok(()),
        Ok(m) => Err(err(
            out,
            format!(
                "{flag}: is {}, not a directory: give {flag} a directory (new or existing) to write into",
                file_kind(&m.file_type()).replace("not a regular file", "a file")
            ),
        )),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(io(out, e)),
    }
}

/// Writes a set of outputs (the tables and plots of `analyze`, `forecast` or `figures`) into
/// `out`, created, as one: `write` puts every file into a hidden staging directory in `out`,
/// which it is given, and only once all are complete are they moved in, each over the file of
/// its name, every target checked before the first is moved. A failure anywhere (a full disk, a
/// signal, a target that cannot be replaced) leaves the previous set as it was, not a mix.
/// `stale(name)` says which files of `out` are of the set though their names vary (a snapshot
/// of another step): those the new set does not hold are removed once it is in. Returns the
/// files written, in `out`.
pub fn write_set(
    out: &Path,
    stale: impl Fn(&str) -> bool,
    write: impl FnOnce(&Path) -> IoResult<Vec<PathBuf>>,
) -> IoResult<Vec<PathBuf>> {
    static CALLS: AtomicU64 = AtomicU64::new(0);
    check_output_dir("--out", out)?;
    let call = CALLS.fetch_add(1, Ordering::Relaxed);
    fs::create_dir_all(out).map_err(|e| io(out, e))?;
    remove_dead_temporaries(out);
    let stage = out.join(format!(".staging.{}.{call}", std::process::id()));
    let staged = fs::create_dir(&stage).map_err(|e| io(&stage, e)).and_then(|_| write(&stage));
    let moved = staged.and_then(|files| move_set_in(out, &files));
    let _ = fs::remove_dir_all(&stage);
    let moved = moved?;
    remove_stale(out, &moved, stale)?;
    Ok(moved)
}

/// Moves the staged `files` into `out`, every target checked before the first is moved: one that
/// cannot be replaced leaves the previous set whole.
fn move_set_in(out: &Path, files: &[PathBuf]) -> IoResult<Vec<PathBuf>> {
    let targets = files
        .iter()
        .map(|f| {
            let to = out.join(f.file_name().ok_or_else(|| err(f, "not a file name"))?);
            replaceable(&to).map(|target| (to, target))
        })
        .collect::<Result<Vec<_>, _>>()?;
    files
        .iter()
        .zip(targets)
        .map(|(f, (to, target))| fs::rename(f, &target).map(|_| to.clone()).map_err(|e| io(&to, e)))
        .collect()
}

/// Removes the files of `out` that `stale` says are of the set and that the set just moved in
/// (`kept`) does not hold.
fn remove_stale(out: &Path, kept: &[PathBuf], stale: impl Fn(&str) -> bool) -> IoResult<()> {
    let entries = fs::read_dir(out).map_err(|e| io(out, e))?;
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        let path = entry.path();
        if stale(&name) && !kept.contains(&path) && entry.file_type().is_ok_and(|t| t.is_file()) {
            fs::remove_file(&path).map_err(|e| io(&path, e))?;
        }
    }
    Ok(())
}

/// The largest text file read as input: a config file, a sweep file or a `run.json` holds a
/// few kilobytes; anything near this is not one, and would be read whole into memory.
pub const MAX_TEXT_INPUT_BYTES: u64 = 1 << 20;

/// Checks that the input file `path` (given as `what`, e.g. `--config`) is a regular file of at
/// most `max_bytes`, before it is opened: opening a FIFO blocks until a writer comes, and a
/// device such as `/dev/zero` never ends. A symbolic link is followed to what it points at.
pub fn check_input(path: &Path, what: &str, max_bytes: u64) -> IoResult<()> {
    let meta = fs::metadata(path).map_err(|e| io(path, e))?;
    if !meta.is_file() {
        let kind = file_kind(&meta.file_type());
        return Err(err(path, format!("is {kind}, not a regular file: refused as {what}")));
    }
    if meta.len() > max_bytes {
        return Err(err(path, format!("{} bytes: larger than any {what} ({max_bytes} bytes at most)", meta.len())));
    }
    Ok(())
}

/// Reads the input file `path` whole once [`check_input`] accepts it; no more than `max_bytes`
/// are read should it grow meanwhile.
pub fn read_input(path: &Path, what: &str, max_bytes: u64) -> IoResult<Vec<u8>> {
    check_input(path, what, max_bytes)?;
    let mut bytes = Vec::new();
    File::open(path).and_then(|f| f.take(max_bytes + 1).read_to_end(&mut bytes)).map_err(|e| io(path, e))?;
    if bytes.len() as u64 > max_bytes {
        return Err(err(path, format!("grew past {max_bytes} bytes while read: larger than any {what}")));
    }
    Ok(bytes)
}

/// [`read_input`] of a UTF-8 text file.
pub fn read_text_input(path: &Path, what: &str) -> IoResult<String> {
    String::from_utf8(read_input(path, what, MAX_TEXT_INPUT_BYTES)?)
        .map_err(|e| err(path, format!("not UTF-8 text ({e}): refused as {what}")))
}

/// Removes the temporary files a killed writer left in `dir` (call it holding the directory's
/// [`RunLock`], so that no live writer's file is taken).
pub fn remove_stale_temporaries(dir: &Path) {
    let Ok(entries) = fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let name = name.to_string_lossy();
        if name.starts_with('.') && name.ends_with(".tmp") {
            let _ = fs::remove_file(entry.path());
        }
    }
}

/// Removes what writers that are no longer alive left in `dir`: temporary files
/// (`.NAME.PID.N.tmp`, of [`write_atomic`]) and staging directories (`.staging.PID.N`, of
/// `analyze`), each named by its writer's process id. A living writer's are left alone, so this
/// needs no lock (`analyze` and `figures` take none).
pub fn remove_dead_temporaries(dir: &Path) {
    let Ok(entries) = fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        let pid = if let Some(rest) = name.strip_prefix(".staging.") {
            rest.split('.').next()
        } else if name.starts_with('.') && name.ends_with(".tmp") {
            name.trim_end_matches(".tmp").rsplit('.').nth(1)
        } else {
            None
        };
        let Some(pid) = pid.and_then(|p| p.parse::<u32>().ok()) else { continue };
        if pid == std::process::id() || Path::new(&format!("/proc/{pid}")).exists() {
            continue;
        }
        let path = entry.path();
        let _ = if entry.file_type().is_ok_and(|t| t.is_dir()) {
            fs::remove_dir_all(&path)
        } else {
            fs::remove_file(&path)
        };
    }
}

/// The one writer of a run directory: an OS lock on `DIR/.lock`, held while this value lives and
/// released by the OS when the process ends however it ends (a stale file locks nothing). The
/// holder's process id is written into the file, for the error the next writer gets.
#[derive(Debug)]
pub struct RunLock {
    _file: File,
}

impl RunLock {
    pub const FILE: &'static str = ".lock";

    /// Takes the lock of `dir` (which must exist), or says which process holds it.
    pub fn acquire(dir: &Path) -> IoResult<Self> {
        Self::try_acquire(dir)?.map_err(|holder| {
            let who = holder.map(|pid| format!("process {pid}")).unwrap_or_else(|| "another process".into());
            err(
                dir,
                format!(
                    "{who} is writing this run directory (one writer per directory): wait for it to end, or stop it, \
                     then try again"
                ),
            )
        })
    }

    /// Takes the lock of `dir`, or gives the process id of its holder (None where the file does
    /// not say) as the inner error.
    pub fn try_acquire(dir: &Path) -> IoResult<Result<Self, Option<u32>>> {
        let path = dir.join(Self::FILE);
        let mut options = fs::OpenOptions::new();
        options.read(true).write(true).create(true).truncate(false);
        // Never through a symbolic link: the pid would be written into whatever it points at.
        #[cfg(unix)]
        std::os::unix::fs::OpenOptionsExt::custom_flags(&mut options, libc::O_NOFOLLOW);
        // Anything but a regular file (a FIFO, a device) cannot be this program's lock: flock on
        // it fails with an error that names neither the file nor the cause.
        if let Ok(m) = fs::symlink_metadata(&path) {
            if !m.is_file() && !m.file_type().is_symlink() {
                let kind = file_kind(&m.file_type());
                return Err(err(
                    &path,
                    format!("is {kind}, not a regular file: not this program's lock file; remove it, then try again"),
                ));
            }
        }
        let mut file = options.open(&path).map_err(|e| match fs::symlink_metadata(&path) {
            Ok(m) if m.file_type().is_symlink() => {
                err(&path, "a symbolic link, not this program's lock file: remove it, then try again")
            }
            _ => io(&path, e),
        })?;
        match file.try_lock() {
            Ok(()) => {}
            Err(fs::TryLockError::WouldBlock) => {
                let mut holder = String::new();
                let _ = file.read_to_string(&mut holder);
                return Ok(Err(holder.trim().parse::<u32>().ok()));
            }
            Err(fs::TryLockError::Error(e)) => return Err(io(&path, e)),
        }
        file.set_len(0).map_err(|e| io(&path, e))?;
        writeln!(file, "{}", std::process::id()).map_err(|e| io(&path, e))?;
        Ok(Ok(RunLock { _file: file }))
    }
}

impl RunRecord {
    pub fn path(dir: &Path) -> PathBuf {
        dir.join("run.json")
    }

    pub fn save(&self, dir: &Path) -> IoResult<()> {
        let path = Self::path(dir);
        write_atomic(&path, |w| w.write_all(self.to_json().as_bytes()).map_err(|e| io(&path, e)))
    }

    /// Reads and checks `DIR/run.json`, naming what is wrong.
    pub fn load(dir: &Path) -> IoResult<Self> {
        let path = Self::path(dir);
        if !dir.is_dir() {
            return Err(err(dir, "no such directory"));
        }
        if !path.exists() {
            return Err(err(&path, "no such file (is this a run directory?)"));
        }
        let text = read_text_input(&path, "a run record")?;
        let value: serde_json::Value =
            serde_json::from_str(&text).map_err(|e| err(&path, format!("not valid JSON: {e}")))?;
        if value.get("format").and_then(|f| f.as_str()) != Some(FORMAT) {
            return Err(err(&path, format!("not a record of this program (no \"format\": \"{FORMAT}\")")));
        }
        match value.get("format_version") {
            Some(v) if v.as_u64() == Some(FORMAT_VERSION as u64) => {}
            Some(v) => {
                return Err(err(
                    &path,
                    format!(
                        "`format_version` = {v}: this program reads format_version {FORMAT_VERSION} (a run written \
                         by another version of it: read it with that version)"
                    ),
                ))
            }
            None => {
                return Err(err(
                    &path,
                    format!("no `format_version`: not a complete run record (this program writes {FORMAT_VERSION})"),
                ))
            }
        }
        // A run continues with the parameters it was started with, never with a default: a record
        // without one (hand-edited, or of an older version that lacked it) is refused by name.
        let given = value
            .get("params")
            .and_then(|p| p.as_object())
            .ok_or_else(|| err(&path, "no `params` table: not a complete run record"))?;
        let defaults = serde_json::to_value(Params::default()).expect("the defaults serialise");
        let defaults = defaults.as_object().expect("params are a table");
        if let Some((k, d)) = defaults.iter().find(|(k, _)| !given.contains_key(k.as_str())) {
            return Err(err(
                &path,
                format!(
                    "parameter `params.{k}` is missing: a run resumes only with the values it started with, never \
                     a default; add `\"{k}\": VALUE` with the run's value (this version's default is {d})"
                ),
            ));
        }
        let mut de = serde_json::Deserializer::from_str(&text);
        let record: RunRecord = serde_path_to_error::deserialize(&mut de)
            .map_err(|e| err(&path, format!("`{}`: {}", e.path(), e.inner())))?;
        record.params.validate().map_err(|e| RunError::from(e).context(path.display().to_string()))?;
        if record.frame_interval == 0 {
            return Err(err(&path, "`frame_interval` = 0: must be ≥ 1"));
        }
        Ok(record)
    }
}

/// Name of the frame file of a step: `frames/frame_0011000.npz` ([`frame_file_name`]).
pub fn frame_path(dir: &Path, step: u64) -> PathBuf {
    dir.join("frames").join(frame_file_name(step))
}

fn npz_err(path: &Path) -> impl Fn(ndarray_npy::WriteNpzError) -> RunError + '_ {
    move |e| err(path, e)
}

/// [`formats::check_finite`], the error naming the file.
fn finite<'a>(path: &Path, name: &str, values: impl Iterator<Item = &'a f64>) -> IoResult<()> {
    formats::check_finite(name, values).map_err(|e| err(path, e))
}

type Npz = NpzWriter<Cursor<Vec<u8>>>;

/// Writes an `.npz` built in memory. The archive is finished before a byte reaches the disk, so a
/// full disk fails in one plain write (a zip writer dropped unfinished on an IO error would try
/// again and print "ZipWriter drop failed" to stderr).
fn write_npz(path: &Path, build: impl FnOnce(&mut Npz) -> Result<(), ndarray_npy::WriteNpzError>) -> IoResult<()> {
    let e = npz_err(path);
    let mut z = NpzWriter::new_compressed(Cursor::new(Vec::new()));
    build(&mut z).map_err(&e)?;
    let bytes = z.finish().map_err(&e)?.into_inner();
    write_atomic(path, |w| w.write_all(&bytes).map_err(|x| io(path, x)))
}

/// Per-cell arrays of a frame or checkpoint: patches (x0, y0, w, h) and the concatenated fields.
fn patch_table(patches: impl Iterator<Item = Patch>, n: usize) -> Array2<i64> {
    let mut t = Array2::<i64>::zeros((n, 4));
    for (i, p) in patches.enumerate() {
        t[[i, 0]] = p.x0 as i64;
        t[[i, 1]] = p.y0 as i64;
        t[[i, 2]] = p.w as i64;
        t[[i, 3]] = p.h as i64;
    }
    t
}

fn complex_field(v: &[C64], l: usize) -> Array3<f64> {
    Array3::from_shape_fn((l, l, 2), |(y, x, c)| if c == 0 { v[y * l + x].re } else { v[y * l + x].im })
}

/// Writes one frame of the current state (after [`Monolayer::evaluate_now`] so that velocities
/// belong to this φ), atomically; the format is [`formats::frame_bytes`]'s.
pub fn write_frame(m: &mut Monolayer, path: &Path) -> IoResult<()> {
    let bytes = formats::frame_bytes(m).map_err(npz_err(path))?;
    write_atomic(path, |w| w.write_all(&bytes).map_err(|x| io(path, x)))
}

/// The array of a checkpoint that holds the seed and parameters it was stepped with (JSON text as
/// bytes), and for a run's own checkpoints its engine and frame interval: a resume under other
/// ones would continue another trajectory from this state.
const RUN_PARAMS: &str = "run_params";

fn run_params_json(params: &Params, seed: u64) -> serde_json::Value {
    serde_json::json!({ "seed": seed, "params": params })
}

/// Writes the exact state (f64 bits, padded patches, the solver's warm start and corrector
/// shift), and the seed and parameters it belongs to.
pub fn write_checkpoint(m: &Monolayer, path: &Path) -> IoResult<()> {
    write_state(m, path, run_params_json(m.params(), m.seed()))
}

/// [`write_checkpoint`] of a run's state: with the engine that stepped it and the run's frame
/// interval from its `record`, so that a resume under another (run.json edited) is refused by name.
pub fn write_run_checkpoint(m: &Monolayer, path: &Path, record: &RunRecord) -> IoResult<()> {
    let mut key = run_params_json(m.params(), m.seed());
    key["engine"] = engine_name(&record.engine).into();
    key["frame_interval"] = record.frame_interval.into();
    write_state(m, path, key)
}

/// The engine a record names, as `run.json` writes it (an unknown name as it is, for the error).
fn engine_name(recorded: &str) -> String {
    match Engine::parse(if recorded.is_empty() { "cpu" } else { recorded }) {
        Ok(e) => e.name().to_string(),
        Err(_) => recorded.to_string(),
    }
}

fn write_state(m: &Monolayer, path: &Path, key: serde_json::Value) -> IoResult<()> {
    let s = m.state();
    let l = m.params().box_size;
    let n = s.cells.len();
    let patches = patch_table(s.cells.iter().map(|(p, _)| *p), n);
    let mut offsets = vec![0i64];
    let mut phi = Vec::new();
    for (_, f) in &s.cells {
        phi.extend_from_slice(f);
        offsets.push(phi.len() as i64);
    }
    let warm = complex_field(&s.warm_start, l);
    let shift = complex_field(&s.corrector_shift, l);
    let substrate = Array2::from_shape_vec((l, l), s.substrate.clone()).expect("L×L");
    let key = key.to_string().into_bytes();
    write_npz(path, |z| {
        z.add_array(RUN_PARAMS, &Array1::from(key))?;
        z.add_array("step", &arr0(s.step as i64))?;
        z.add_array("patches", &patches)?;
        z.add_array("phi_padded", &Array1::from(phi))?;
        z.add_array("phi_offsets", &Array1::from(offsets))?;
        z.add_array("warm_start", &warm)?;
        z.add_array("corrector_shift", &shift)?;
        z.add_array("substrate", &substrate)
    })
}

/// Checks every array's header in the `.npz` at `path` before anything is allocated from it
/// ([`formats::check_npz_headers`]).
fn check_npz_file_headers(path: &Path, max_values: u64) -> IoResult<()> {
    check_input(path, "a checkpoint", MAX_FRAME_BYTES)?;
    let file = File::open(path).map_err(|e| io(path, e))?;
    formats::check_npz_headers(BufReader::new(file), max_values).map_err(|e| err(path, e))
}

/// Reads a checkpoint written by [`write_checkpoint`].
pub fn read_checkpoint(path: &Path, l: usize) -> IoResult<State> {
    check_npz_file_headers(path, formats::max_array_values(l))?;
    let file = File::open(path).map_err(|e| io(path, e))?;
    let mut z = NpzReader::new(BufReader::new(file)).map_err(|e| err(path, e))?;
    let e = |name: &str| {
        let name = name.to_string();
        move |x: ndarray_npy::ReadNpzError| err(path, format!("array `{name}`: {x}"))
    };
    let step: ndarray::Array0<i64> = z.by_name("step").map_err(e("step"))?;
    let patches: Array2<i64> = z.by_name("patches").map_err(e("patches"))?;
    let phi: Array1<f64> = z.by_name("phi_padded").map_err(e("phi_padded"))?;
    let offsets: Array1<i64> = z.by_name("phi_offsets").map_err(e("phi_offsets"))?;
    let warm: Array3<f64> = z.by_name("warm_start").map_err(e("warm_start"))?;
    // Checkpoints written before the corrector shift was kept (2026-12-04) have none: the
    // next corrector starts from the predictor's solution alone, as those runs did.
    let has_shift =
        z.names().map_err(|x| err(path, x))?.iter().any(|n| n.trim_end_matches(".npy") == "corrector_shift");
    let shift: Array3<f64> =
        if has_shift { z.by_name("corrector_shift").map_err(e("corrector_shift"))? } else { Array3::zeros((l, l, 2)) };
    let substrate: Array2<f64> = z.by_name("substrate").map_err(e("substrate"))?;
    if warm.dim() != (l, l, 2) || shift.dim() != (l, l, 2) || substrate.dim() != (l, l) {
        return Err(err(path, format!("lattice arrays are not {l}×{l}")));
    }
    let n = patches.nrows();
    if offsets.len() != n + 1 || patches.ncols() != 4 {
        return Err(err(path, "patch table and offsets disagree"));
    }
    let step = step.into_scalar();
    if step < 0 {
        return Err(err(path, format!("array `step` = {step}: a step is ≥ 0")));
    }
    finite(path, "phi_padded", phi.iter())?;
    finite(path, "warm_start", warm.iter())?;
    finite(path, "corrector_shift", shift.iter())?;
    finite(path, "substrate", substrate.iter())?;
    if let Some((k, v)) = substrate.iter().enumerate().find(|(_, &v)| v <= 0.0) {
        return Err(err(path, format!("array `substrate` holds {v} at index {k}: a friction map is > 0")));
    }
    let mut cells = Vec::with_capacity(n);
    for i in 0..n {
        let (a, b) = (offsets[i], offsets[i + 1]);
        if a < 0 || a > b || b as usize > phi.len() {
            return Err(err(path, format!("cell {i}: offsets out of range")));
        }
        let (a, b) = (a as usize, b as usize);
        let [x0, y0, w, h] = [0, 1, 2, 3].map(|k| patches[[i, k]]);
        if [x0, y0, w, h].iter().any(|&v| v < 0 || v as usize >= l) {
            return Err(err(path, format!("cell {i}: patch ({x0}, {y0}, {w}, {h}) does not fit the {l}×{l} lattice")));
        }
        if w == 0 || h == 0 {
            return Err(err(
                path,
                format!(
                    "cell {i}: patch at ({x0}, {y0}) is {w}×{h} sites: a cell's patch is at least 1×1 (a damaged file)"
                ),
            ));
        }
        let p = Patch { x0: x0 as usize, y0: y0 as usize, w: w as usize, h: h as usize };
        if b - a != p.padded_len() {
            return Err(err(
                path,
                format!(
                    "cell {i}: {} values of φ for a {w}×{h} patch, which holds {} with its padding (a damaged file)",
                    b - a,
                    p.padded_len()
                ),
            ));
        }
        cells.push((p, phi.slice(ndarray::s![a..b]).to_vec()));
    }
    let complex = |a: &Array3<f64>| (0..l * l).map(|k| C64::new(a[[k / l, k % l, 0]], a[[k / l, k % l, 1]])).collect();
    Ok(State {
        step: step as u64,
        cells,
        warm_start: complex(&warm),
        corrector_shift: complex(&shift),
        substrate: substrate.iter().copied().collect(),
    })
}

/// Checks that the checkpoint at `path` was written with the seed and parameters of `record`
/// (and, where it records them, its engine and frame interval), naming the first that differs:
/// `run.json` edited after the run started would otherwise continue one trajectory under
/// another's parameters, or be blamed on the checkpoint. Read before the state itself, whose
/// arrays are checked against the record's lattice. Checkpoints written before they held their
/// parameters are not checked.
pub fn check_checkpoint_params(path: &Path, record: &RunRecord) -> IoResult<()> {
    // Bounded by the largest lattice a run may have, not the record's: an edited box_size is
    // named below, not taken for a damaged checkpoint.
    check_npz_file_headers(path, formats::max_array_values(MAX_BOX_SIZE))?;
    let file = File::open(path).map_err(|e| io(path, e))?;
    let mut z = NpzReader::new(BufReader::new(file)).map_err(|e| err(path, e))?;
    let has_key = z.names().map_err(|x| err(path, x))?.iter().any(|n| n.trim_end_matches(".npy") == RUN_PARAMS);
    if !has_key {
        return Ok(());
    }
    let bytes: Array1<u8> = z.by_name(RUN_PARAMS).map_err(|x| err(path, format!("array `{RUN_PARAMS}`: {x}")))?;
    let stored: serde_json::Value = serde_json::from_slice(&bytes.to_vec())
        .map_err(|x| err(path, format!("array `{RUN_PARAMS}`: not the JSON of a run's parameters: {x}")))?;
    let step: ndarray::Array0<i64> = z.by_name("step").map_err(|x| err(path, format!("array `step`: {x}")))?;
    let given = run_params_json(&record.params, record.seed);
    let mut pairs = vec![("seed".to_string(), stored.get("seed").cloned(), given.get("seed").cloned())];
    if let Some(table) = given.get("params").and_then(|p| p.as_object()) {
        // `active_steps` says only where the trajectory ends: raising it extends the same run.
        for (k, v) in table.iter().filter(|(k, _)| *k != "active_steps") {
            pairs.push((k.clone(), stored.get("params").and_then(|p| p.get(k)).cloned(), Some(v.clone())));
        }
    }
    pairs.push(("frame_interval".into(), stored.get("frame_interval").cloned(), Some(record.frame_interval.into())));
    // The state of step 0 is the random disks, which every engine starts from (a new run takes
    // its engine after its first checkpoint); from the first step on, it is the engine's.
    if step.into_scalar() > 0 {
        let engine = engine_name(&record.engine);
        pairs.push(("engine".into(), stored.get("engine").cloned(), Some(engine.into())));
    }
    // A parameter newer than the checkpoint is not in it, and has its default there.
    let differs = pairs.into_iter().find(|(_, s, g)| s.is_some() && s != g);
    match differs {
        None => Ok(()),
        Some((k, s, g)) => {
            let show = |v: Option<serde_json::Value>| v.map(|v| v.to_string()).unwrap_or_default();
            let (s, g) = (show(s), show(g));
            Err(err(
                &RunRecord::path(path.parent().unwrap_or(Path::new("."))),
                format!(
                    "`{k}` = {g} there, but the checkpoint {} was written with {k} = {s}: a run continues only with \
                     the parameters, frame interval and engine it started with (was run.json edited?); restore \
                     `{k}` to {s}, or start a new run with these parameters in another --out",
                    path.display(),
                ),
            ))
        }
    }
}

// ---- Reading frames (offline analysis) ----

/// One frame of a run: its file and what the analysis needs of it.
#[derive(Clone, Debug)]
pub struct Frame {
    pub path: PathBuf,
    pub data: FrameData,
}

/// A run directory checked for analysis: its record and every frame it has written, in step
/// order, none missing. Every reader of a run's frames (`analyze`, the sweep's tables, the
/// figures, the forecast) goes through it: a frame missing anywhere would be measured as a
/// shorter run or a longer frame interval, and counted as a result that was never measured.
#[derive(Clone, Debug)]
pub struct RunFrames {
    pub dir: PathBuf,
    pub record: RunRecord,
    /// (step, path) of every frame file, sorted by step.
    pub frames: Vec<(u64, PathBuf)>,
}

impl RunFrames {
    /// Opens `dir` as a run with at least one frame: its `run.json` must be this program's, of
    /// this format version, and its frames all there from the first ([`RunRecord::first_frame_step`])
    /// to the last its record names, one every frame interval. Frames are written by an atomic
    /// rename, so every `frame_*.npz` present is complete (a frame being written is a hidden
    /// temporary file, skipped): a run in progress is read up to its last complete frame.
    pub fn open(dir: &Path) -> Result<Self, RunError> {
        let record = RunRecord::load(dir)?;
        let (status, interval) = (record.status.to_string(), record.frame_interval);
        Self::scan(dir, record)?.ok_or_else(|| {
            err(
                &dir.join("frames"),
                format!(
                    "no frames yet (status \"{status}\"); frames are written every {interval} active steps (a run's \
                     frames are in DIR/frames)"
                ),
            )
        })
    }

    /// [`RunFrames::open`], or None for a run whose record says it has written no frame yet (one
    /// that failed or stopped before its first): the sweep's tables and the figures count such a
    /// run by its status alone. Frames missing where the record says there are some are refused.
    pub fn open_if_any(dir: &Path) -> Result<Option<Self>, RunError> {
        Self::scan(dir, RunRecord::load(dir)?)
    }

    fn scan(dir: &Path, record: RunRecord) -> Result<Option<Self>, RunError> {
        let frames_dir = dir.join("frames");
        let mut frames = frame_files(&frames_dir)?;
        if frames.is_empty() {
            return match record.last_frame_step {
                None => Ok(None),
                Some(last) => Err(err(
                    &frames_dir,
                    format!(
                        "no frame files, but run.json records frames from step {} to step {last} (last_frame_step): \
                         they were removed or moved; restore them, or move the run out of where it is read",
                        record.first_frame_step()
                    ),
                )),
            };
        }
        frames.sort();
        if let Some(w) = frames.windows(2).find(|w| w[0].0 == w[1].0) {
            let step = w[0].0;
            let own = frame_path(dir, step);
            let foreign: Vec<String> =
                frames.iter().filter(|f| f.0 == step && f.1 != own).map(|f| f.1.display().to_string()).collect();
            return Err(RunError::DuplicateFrames {
                first: w[0].1.clone(),
                second: w[1].1.clone(),
                step,
                foreign,
                own,
            });
        }
        check_frame_sequence(&frames_dir, &record, &frames)?;
        Ok(Some(RunFrames { dir: dir.to_path_buf(), record, frames }))
    }

    /// Reads every frame in order, each checked against the run ([`read_run_frame`]).
    pub fn read(&self) -> impl Iterator<Item = Result<Frame, RunError>> + '_ {
        self.frames.iter().map(|(step, path)| read_run_frame(path, *step, &self.record.params))
    }
}

/// (step, path) of every `frame_<step>.npz` in `frames_dir`, unsorted; none where the directory
/// does not exist. Anything named like a frame that is not a regular file is refused: a FIFO
/// or a device would block the reader or never end, and a directory would be a frame skipped.
fn frame_files(frames_dir: &Path) -> IoResult<Vec<(u64, PathBuf)>> {
    let entries = match fs::read_dir(frames_dir) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(err(frames_dir, format!("{e} (a run's frames are in DIR/frames)"))),
        Ok(entries) => entries,
    };
    let mut frames = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| io(frames_dir, e))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        let Some(step) = name.strip_prefix("frame_").and_then(|s| s.strip_suffix(".npz")) else { continue };
        let meta = fs::metadata(entry.path()).map_err(|e| io(&entry.path(), e))?;
        if !meta.is_file() {
            let kind = file_kind(&meta.file_type());
            return Err(err(
                &entry.path(),
                format!("is {kind}, not a regular file: not a frame; move it out of frames/"),
            ));
        }
        let step: u64 = step.parse().map_err(|_| err(&entry.path(), "not a frame name (frame_<step>.npz)"))?;
        frames.push((step, entry.path()));
    }
    Ok(frames)
}

/// The steps `from`, `from + every`, … up to `to` as a list for a message: the first ten, then
/// how many more (a gap may span millions of frames).
fn steps_text(from: u64, to: u64, every: u64) -> String {
    let count = (to - from) / every + 1;
    let shown: Vec<String> = (0..count.min(10)).map(|k| (from + k * every).to_string()).collect();
    let more = if count > 10 { format!(" and {} more", count - 10) } else { String::new() };
    format!("step{} {}{more}", if count == 1 { "" } else { "s" }, shown.join(", "))
}

/// Checks that `frames` (sorted, of distinct steps) are every frame of the run from its first
/// to the last its record names, one every frame interval: a frame missing at the start would
/// be measured as a shorter run, one in the middle as one long frame interval (holes would seem
/// to open and close faster), one at the end as a run that ended early.
fn check_frame_sequence(frames_dir: &Path, record: &RunRecord, frames: &[(u64, PathBuf)]) -> IoResult<()> {
    let fi = record.frame_interval;
    let first = record.first_frame_step();
    let (start, start_path) = (frames[0].0, &frames[0].1);
    let restore = "restore them, or move the run out of where it is read";
    if start < first || !(start - first).is_multiple_of(fi) {
        return Err(err(
            start_path,
            format!(
                "step {start} is not a step this run writes a frame at (from step {first}, every frame_interval = \
                 {fi} steps: run.json): not a frame of this run"
            ),
        ));
    }
    if start > first {
        return Err(err(
            frames_dir,
            format!(
                "frames missing at {} before {} (the run's frames start at step {first}, the end of its \
                 relaxation, one every frame_interval = {fi} steps: run.json): {restore}",
                steps_text(first, start - fi, fi),
                start_path.display()
            ),
        ));
    }
    if let Some(w) = frames.windows(2).find(|w| w[1].0 - w[0].0 != fi) {
        let (a, b) = (w[0].0, w[1].0);
        if !(b - a).is_multiple_of(fi) {
            return Err(err(
                &w[1].1,
                format!(
                    "step {b} is not a frame interval after the frame before it ({}, step {a}; run.json: \
                     frame_interval = {fi}): not a frame of this run",
                    w[0].1.display()
                ),
            ));
        }
        return Err(err(
            frames_dir,
            format!(
                "frames missing at {}, between {} and {} (run.json: a frame every frame_interval = {fi} steps): \
                 {restore}, or move the frames after the gap out of the run to measure up to it",
                steps_text(a + fi, b - fi, fi),
                w[0].1.display(),
                w[1].1.display()
            ),
        ));
    }
    let end = frames[frames.len() - 1].0;
    if let Some(last) = record.last_frame_step.filter(|&last| last > end) {
        return Err(err(
            frames_dir,
            format!(
                "frames missing at {} after {} (run.json records frames up to last_frame_step = {last}): {restore}",
                steps_text(end + fi, last, fi),
                frames[frames.len() - 1].1.display()
            ),
        ));
    }
    Ok(())
}

/// Reads the frame of `step` of a run at `path` and checks it against the run: its size, its
/// cells, its φ and the step it holds ([`read_frame`], `check_frame`).
pub fn read_run_frame(path: &Path, step: u64, params: &Params) -> IoResult<Frame> {
    let frame = read_frame(path, params.box_size)?;
    check_frame(&frame, params)?;
    if frame.data.step != step {
        return Err(err(path, format!("holds step {}, its name says {step}", frame.data.step)));
    }
    Ok(frame)
}

/// The largest frame file read: the arrays of a 2,048² run with the cells' φ, deflated, are far
/// smaller. A larger file is not a frame, and reading it whole would exhaust the memory.
const MAX_FRAME_BYTES: u64 = 1 << 32;

/// Reads one frame of a run on an L×L lattice ([`formats::decode_frame_of_box`], the decoder the
/// page uses), checking every array's shape.
pub fn read_frame(path: &Path, l: usize) -> Result<Frame, RunError> {
    // A FIFO or a device would block the reader, or never end.
    let meta = fs::metadata(path).map_err(|e| io(path, e))?;
    if !meta.is_file() {
        return Err(err(path, "not a regular file: not a frame"));
    }
    if meta.len() > MAX_FRAME_BYTES {
        return Err(err(path, format!("{} bytes: larger than any frame ({MAX_FRAME_BYTES} at most)", meta.len())));
    }
    let bytes = fs::read(path).map_err(|e| io(path, e))?;
    let data = formats::decode_frame_of_box(&path.display().to_string(), &bytes, l)?;
    Ok(Frame { path: path.to_path_buf(), data })
}

/// Checks a frame read from a run against the run's record: a frame with cells missing would be
/// measured as holes where the cells are.
pub fn check_frame(frame: &Frame, params: &Params) -> IoResult<()> {
    // A step leaves every φ in [phi_min, phi_max] or fails the run: a frame beyond is damaged.
    let (lo, hi) = (params.phi_min, params.phi_max);
    if let Some(v) = frame.data.cells.iter().flat_map(|(_, phi)| phi.iter()).find(|&&v| !(lo..=hi).contains(&v)) {
        return Err(err(
            &frame.path,
            format!("holds φ = {v}, outside [{lo}, {hi}] where every run stays: a damaged file"),
        ));
    }
    if frame.data.cells.len() != params.n_cells {
        return Err(err(
            &frame.path,
            format!(
                "holds {} cells, the run has n_cells = {}: not a frame of this run",
                frame.data.cells.len(),
                params.n_cells
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn atomic_write_leaves_nothing_on_failure() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.bin");
        let r = write_atomic(&path, |_| Err(RunError::Panicked));
        assert!(r.is_err());
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 0);
        write_atomic(&path, |w| w.write_all(b"ok").map_err(|e| io(&path, e))).unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"ok");
    }
}
