//! The `bouncewear` binary: the command line and the HTTP service, a thin shell around
//! [`bouncewear_model`].
//!
//! Layers, with arrows only downward (a test checks the `use crate::` lines):
//! `cli` | `app` -> `api` | `worker` | `scheduler` | `retention` -> `domain` | `store` | `plots` ->
//! the model.
//! `store` persists `domain` types; `config`, `compute`, `connections` (the accept loop),
//! `telemetry` and `progress` are leaves.

pub mod api;
pub mod app;
pub mod cli;
pub mod compute;
pub mod config;
pub mod connections;
pub mod domain;
pub mod plots;
pub mod progress;
pub mod retention;
pub mod scheduler;
pub mod store;
pub mod telemetry;
pub mod worker;
