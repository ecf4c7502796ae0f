//! Test plans: [`rigfile::plan`] (one plan type and one drive enum for every verb and for
//! `explain`'s proposals), re-exported where the procedures find them.

pub use rigfile::plan::*;
