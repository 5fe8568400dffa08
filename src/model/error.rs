//! Why a simulation stopped.

use crate::model::friction::SolveError;
use crate::model::params::ParamError;

/// Why a simulation stopped or refused to start: invalid parameters, an unstable state, a
/// failed friction solve, a lost cell.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SimError {
    #[error("invalid parameters: {0}")]
    Params(#[from] ParamError),
    #[error(
        "unstable at step {step}: cell {cell} has {quantity} = {value} at site ({x}, {y}), outside [{min}, {max}]; \
         the state before this step is kept"
    )]
    Unstable { step: u64, cell: usize, x: usize, y: usize, quantity: &'static str, value: f64, min: f64, max: f64 },
    #[error("step {step}: {source}; the state before this step is kept")]
    Friction {
        step: u64,
        #[source]
        source: SolveError,
    },
    #[error("step {step}: cell {cell} {what}; the state before this step is kept")]
    CellLost { step: u64, cell: usize, what: String },
    #[error("{0}")]
    Invalid(String),
}
