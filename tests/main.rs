//! The service's integration tests, one binary: built and linked once, and its tests run side by
//! side rather than binary after binary. Each module tests one face of the service (its own
//! documentation says which).

mod support;

mod cli;
mod http;
mod layers;
mod migrations;
mod process;
mod store;
