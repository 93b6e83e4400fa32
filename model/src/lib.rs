//! The physics of bouncewear: McBride & Sharkh (1992), "Electrical contact phenomena during impact",
//! as specified in `docs/model.md`. Pure computation: no IO, no async, no database.
//!
//! | docs/model.md section | what | where |
//! |---|---|---|
//! | 1 (eq. 1-4) | effective mass and stiffness, impact velocity, flight time, peak gap | [`mechanism`] |
//! | 2 (eq. 5-8, 18) | kappa, the restitution solver, its approximation | [`restitution`] |
//! | 3 | ending the bounce sequence | [`operation`] |
//! | 4 (eq. 12, 13) | peak force, impact duration | [`impact`] |
//! | 5 (eq. 16) | arcing, pre-arc, softening, arc energy, electrical restitution | [`arc`] |
//! | 6 | wear over an endurance test | [`wear`] |
//! | 7 (eq. 9, 10, 14, 15, 17, 19) | the paper's closed forms and readings of e, as checks | [`paper_forms`] |
//! | 8, 9 | defaults, validation | [`scenario`] |
//!
//! The physics is written once over [`lanes::Real`]: one `f64`, or a batch of devices in lockstep,
//! with its own `atan` and `exp` ([`elementary`]) so that every CPU computes the same bits.
//!
//! The Monte Carlo engine (jobs, scatter, parallel streams) is [`montecarlo`]; its mergeable summaries
//! and confidence intervals are [`stats`].

pub mod arc;
pub mod calibration;
pub mod elementary;
pub mod error;
pub mod feistel;
pub mod impact;
pub mod lanes;
pub mod life;
mod linalg;
pub mod mechanism;
pub mod montecarlo;
pub mod operation;
pub mod paper_forms;
pub mod restitution;
pub mod scenario;
pub mod stats;
pub mod wear;

pub use error::{FieldError, InputErrorKind, InvalidInput, Pointer};
pub use operation::{
    Bounce, Conditions, Fidelity, Needs, Operation, Outcome, Simulation, simulate,
};
pub use scenario::{Scenario, ScenarioSpec};
