//! `rig` host library.
