//! Rig physics.
#![cfg_attr(not(test), no_std)]
