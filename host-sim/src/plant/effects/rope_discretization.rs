//! Rope discretization: N lumped elements per rope side instead of one.

/// Rope discretization: N lumped elements per rope side instead of one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RopeDiscretization {
    /// Elements per rope side (1: the paper's lumping).
    pub elements: usize,
}
