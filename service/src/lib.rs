//! The `bouncewear` binary: the command line and the HTTP service, a thin shell around
//! [`bouncewear_model`].

pub mod api;
pub mod app;
pub mod bench;
pub mod cli;
pub mod config;
pub mod errors;
pub mod plots;
pub mod progress;
pub mod schedule;
pub mod scheduler;
pub mod store;
pub mod telemetry;
pub mod worker;
