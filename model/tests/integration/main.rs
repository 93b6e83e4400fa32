//! The model's integration tests, one binary: each file was a binary of its own, and each linked
//! and optimised its own copy of what it used (13 binaries, 140 s of the optimiser on two cores).
//! `cargo test -p bouncewear-model --test integration rare::` runs one file's tests.

mod arc_law;
mod compare;
mod engine_reference;
mod groups;
mod kernels;
mod montecarlo;
mod operation;
mod paper_forms;
mod rare;
mod scatter;
mod sensitivity;
mod sobol_reference;
mod support;
mod validation;
mod wear;
