//! Hardware-free control core of the rig firmware.
#![cfg_attr(not(test), no_std)]
