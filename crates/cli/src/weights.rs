//! The relative weights of the functional-map energy's four terms, as
//! flags of `fmaps match` and `fmaps batch`.

use fmaps::pipeline::MatchParams;
use fmaps::solve::PerTerm;

/// The library's default weights, which the flags show.
fn defaults() -> PerTerm {
    MatchParams::default().energy.weights
}

/// `--w-descr`, `--w-lap`, `--w-dcomm`, `--w-orient`: relative weights
/// (only their ratios matter; each term is first divided by its size for
/// a generic map, so that pyFM's weights mean the same here).
#[derive(clap::Args, Debug, Clone)]
pub(crate) struct WeightFlags {
    /// Relative weight of descriptor preservation ‖C A − B‖².
    #[arg(long, default_value_t = defaults().descr, help_heading = "Energy weights", allow_negative_numbers = true)]
    w_descr: f64,
    /// Relative weight of Laplacian commutativity.
    #[arg(long, default_value_t = defaults().lap, help_heading = "Energy weights", allow_negative_numbers = true)]
    w_lap: f64,
    /// Relative weight of descriptor commutativity (the descriptors'
    /// multiplication operators).
    #[arg(long, default_value_t = defaults().dcomm, help_heading = "Energy weights", allow_negative_numbers = true)]
    w_dcomm: f64,
    /// Relative weight of the orientation-preserving term (0 = off).
    #[arg(long, default_value_t = defaults().orient, help_heading = "Energy weights", allow_negative_numbers = true)]
    w_orient: f64,
}

impl WeightFlags {
    /// The weights given (checked with the other parameters: finite,
    /// non-negative, a positive sum).
    pub(crate) fn weights(&self) -> PerTerm {
        PerTerm {
            descr: self.w_descr,
            lap: self.w_lap,
            dcomm: self.w_dcomm,
            orient: self.w_orient,
        }
    }
}
