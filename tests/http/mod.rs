//! The HTTP API of docs/contract.md against the real application, run in-process on a real
//! database file and port, one module per resource.

mod calibrations;
mod compare;
mod events;
mod jobs;
mod limits;
mod postgres;
mod query;
mod rare;
mod remote;
mod schedules;
mod simulate;
mod strict;
mod system;
