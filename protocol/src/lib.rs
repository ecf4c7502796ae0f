//! Wire format between the rig firmware and the host.
#![cfg_attr(not(any(test, feature = "std")), no_std)]
