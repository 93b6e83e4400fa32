//! The `bouncewear` binary: command line and (later) the HTTP service, a thin shell around
//! [`bouncewear_model`].

pub mod bench;
pub mod cli;
pub mod progress;
