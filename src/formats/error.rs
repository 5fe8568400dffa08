//! The errors of this layer, by cause. Each one's `Display` is the message the user reads (on
//! stderr through `run`, or on the page), word for word as when these functions returned text.

use ndarray_npy::WriteNpzError;

use crate::model::SimError;

/// What is wrong with a file's bytes, or what stopped writing them.
#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    /// A frame file's bytes that are not a frame (of this run): `NAME: what is wrong`.
    #[error("{name}: {source}")]
    Frame {
        name: String,
        #[source]
        source: Box<FormatError>,
    },
    /// An `.npz` archive, or an array in it, that cannot be read or does not hold what a frame
    /// holds (its shape, its cells, its patches): what is wrong, naming the array.
    #[error("{0}")]
    Npz(String),
    /// An array holding NaN, an infinity or an absurd magnitude: a damaged file.
    #[error("array `{array}` holds {value} at index {index}: a damaged file")]
    NotFinite { array: String, value: f64, index: usize },
    /// The state to be written could not be evaluated.
    #[error(transparent)]
    Simulation(#[from] SimError),
    /// The arrays of a frame could not be written.
    #[error("writing the frame: {0}")]
    Write(#[source] WriteNpzError),
    /// A run status `run.json` does not know.
    #[error("unknown status \"{0}\" (running, finished, failed: …, stopped: …)")]
    UnknownStatus(String),
    /// An engine neither `cpu` nor `gpu`.
    #[error("engine {0:?}: must be cpu or gpu")]
    UnknownEngine(String),
}

/// A result of this layer.
pub type FormatResult<T> = Result<T, FormatError>;

#[cfg(test)]
mod tests {
    use super::*;

    /// Each variant prints what the text it replaced printed, compared with that text's format.
    #[test]
    fn messages_are_the_old_strings() {
        let inner = FormatError::Npz("not a readable .npz: bad".into());
        let name = "frame_0000070.npz";
        assert_eq!(
            FormatError::Frame { name: name.into(), source: Box::new(inner) }.to_string(),
            format!("{name}: {}", "not a readable .npz: bad")
        );
        let (array, value, index) = ("phi", f64::NAN, 3usize);
        assert_eq!(
            FormatError::NotFinite { array: array.into(), value, index }.to_string(),
            format!("array `{array}` holds {value} at index {index}: a damaged file")
        );
        let big = 1e300_f64;
        assert_eq!(
            FormatError::NotFinite { array: "time".into(), value: big, index: 0 }.to_string(),
            format!("array `time` holds {big} at index 0: a damaged file")
        );
        let sim = SimError::Invalid("x".into());
        assert_eq!(FormatError::Simulation(SimError::Invalid("x".into())).to_string(), sim.to_string());
        let full = || WriteNpzError::Zip(zip::result::ZipError::Io(std::io::Error::other("full")));
        let text = format!("writing the frame: {}", full());
        let w = full();
        assert_eq!(FormatError::Write(w).to_string(), text);
        let s = "done";
        assert_eq!(
            FormatError::UnknownStatus(s.into()).to_string(),
            format!("unknown status \"{s}\" (running, finished, failed: …, stopped: …)")
        );
        let other = "tpu";
        assert_eq!(
            FormatError::UnknownEngine(other.into()).to_string(),
            format!("engine {other:?}: must be cpu or gpu")
        );
    }
}
