//! The diagnosis's error type: the lower crates' errors, a message, and what
//! a step was doing when it failed ([`Context`]).

use std::fmt::Display;

/// Why an identification or a step of the diagnosis failed.
///
/// Its message is the whole story, context first (`"`travel_up_m70.5`:
/// simulating the travel with ...: the drive tripped at ..."`), so `{e}` and
/// `{e:#}` print the same.
#[derive(Debug, thiserror::Error)]
pub enum DiagnosisError {
    /// A signal analysis refused its input.
    #[error(transparent)]
    Analysis(#[from] dsp::AnalysisError),
    /// A closed-loop simulation stopped.
    #[error(transparent)]
    Sim(#[from] closed_loop::SimError),
    /// A free-decay simulation failed.
    #[error(transparent)]
    FreeDecay(#[from] plant::free_decay::FreeDecayError),
    /// A plot could not be drawn.
    #[error(transparent)]
    Plot(#[from] plots::PlotError),
    /// A report file could not be written.
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// A CSV table could not be written.
    #[error(transparent)]
    Csv(#[from] csv::Error),
    /// The JSON report could not be serialised.
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    /// What went wrong, in words.
    #[error("{0}")]
    Message(String),
    /// An error with what was being done when it happened.
    #[error("{context}: {cause}")]
    Context {
        /// What was being done.
        context: String,
        /// The error it met.
        cause: Box<DiagnosisError>,
    },
}

/// A result of the diagnosis.
pub type Result<T, E = DiagnosisError> = std::result::Result<T, E>;

/// Names what a step was doing when its result is an error (or `None`).
pub trait Context<T> {
    /// The error, or `None`, with `context` in front.
    fn context<C: Display>(self, context: C) -> Result<T>;
    /// As [`Context::context`], the context made only on an error.
    fn with_context<C: Display, F: FnOnce() -> C>(self, context: F) -> Result<T>;
}

impl<T, E: Into<DiagnosisError>> Context<T> for std::result::Result<T, E> {
    fn context<C: Display>(self, context: C) -> Result<T> {
        self.map_err(|e| DiagnosisError::Context { context: context.to_string(), cause: Box::new(e.into()) })
    }

    fn with_context<C: Display, F: FnOnce() -> C>(self, context: F) -> Result<T> {
        self.map_err(|e| DiagnosisError::Context { context: context().to_string(), cause: Box::new(e.into()) })
    }
}

impl<T> Context<T> for Option<T> {
    fn context<C: Display>(self, context: C) -> Result<T> {
        self.ok_or_else(|| DiagnosisError::Message(context.to_string()))
    }

    fn with_context<C: Display, F: FnOnce() -> C>(self, context: F) -> Result<T> {
        self.ok_or_else(|| DiagnosisError::Message(context().to_string()))
    }
}

/// Returns a [`DiagnosisError::Message`] made by `format!`.
macro_rules! bail {
    ($($arg:tt)*) => {
        return Err($crate::error::DiagnosisError::Message(format!($($arg)*)))
    };
}
pub(crate) use bail;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn context_comes_first_and_the_message_is_the_whole_chain() {
        let inner: Result<()> = Err(DiagnosisError::Message("diverged".into()));
        let e = inner.context("simulating").context("`t1`").unwrap_err();
        assert_eq!(e.to_string(), "`t1`: simulating: diverged");
        assert_eq!(format!("{e:#}"), e.to_string());
        let none: Option<u8> = None;
        assert_eq!(none.with_context(|| "no column").unwrap_err().to_string(), "no column");
    }
}
