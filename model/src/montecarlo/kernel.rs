//! Which code runs the devices: one at a time, or `N` in lockstep in loops compiled for an
//! instruction set the CPU has, chosen at run time.
//!
//! Every kernel runs the same generic code ([`crate::lanes::Real`]) and, as that code uses only
//! correctly rounded operations, gives the same bits: the choice changes the speed, never a number.
//! A build runs on any x86_64 (SSE2 is the baseline) and compiles on any other architecture, where
//! only the portable kernels exist.

use crate::lanes::{Lanes, Real};

/// An instruction set the lockstep loops are compiled for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Isa {
    /// What the build targets (SSE2 on x86_64).
    Portable,
    /// AVX2, four f64 lanes per register.
    Avx2,
    /// AVX-512F, eight f64 lanes per register.
    Avx512,
}

impl Isa {
    pub const ALL: [Isa; 3] = [Isa::Portable, Isa::Avx2, Isa::Avx512];

    /// Whether this CPU runs it.
    pub fn available(self) -> bool {
        match self {
            Isa::Portable => true,
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => std::arch::is_x86_feature_detected!("avx2"),
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => std::arch::is_x86_feature_detected!("avx512f"),
            #[cfg(not(target_arch = "x86_64"))]
            Isa::Avx2 | Isa::Avx512 => false,
        }
    }

    pub fn as_str(self) -> &'static str {
        match self {
            Isa::Portable => "portable",
            Isa::Avx2 => "avx2",
            Isa::Avx512 => "avx512",
        }
    }
}

/// Devices per lockstep batch that a kernel may have (1 is one device at a time).
pub const LANE_COUNTS: [usize; 4] = [1, 4, 8, 16];

/// An instruction set and a number of lanes, checked against this CPU.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Kernel {
    isa: Isa,
    lanes: usize,
}

impl Kernel {
    /// One device at a time.
    pub const SCALAR: Kernel = Kernel {
        isa: Isa::Portable,
        lanes: 1,
    };

    /// The kernel, if this CPU runs its instruction set and `lanes` is one of [`LANE_COUNTS`]. One
    /// lane is [`Kernel::SCALAR`] whatever the instruction set.
    pub fn new(isa: Isa, lanes: usize) -> Option<Kernel> {
        if lanes == 1 {
            return Some(Kernel::SCALAR);
        }
        (isa.available() && LANE_COUNTS.contains(&lanes)).then_some(Kernel { isa, lanes })
    }

    /// The fastest kernel on this CPU, as measured (docs/performance.md).
    pub fn best() -> Kernel {
        let isa = if Isa::Avx512.available() {
            Isa::Avx512
        } else if Isa::Avx2.available() {
            Isa::Avx2
        } else {
            Isa::Portable
        };
        Kernel { isa, lanes: 8 }
    }

    /// Every kernel this CPU runs, [`Kernel::SCALAR`] first.
    pub fn all() -> Vec<Kernel> {
        let mut kernels = Vec::new();
        for kernel in Isa::ALL
            .into_iter()
            .flat_map(|isa| LANE_COUNTS.map(|lanes| Kernel::new(isa, lanes)))
            .flatten()
        {
            if !kernels.contains(&kernel) {
                kernels.push(kernel);
            }
        }
        kernels
    }

    pub fn isa(self) -> Isa {
        self.isa
    }

    pub fn lanes(self) -> usize {
        self.lanes
    }

    /// Runs `work` on this kernel's lanes, compiled for its instruction set.
    pub(crate) fn run<W: LaneWork>(self, work: W) {
        match (self.isa, self.lanes) {
            (_, 1) => work.run::<f64>(),
            (Isa::Portable, 4) => work.run::<Lanes<4>>(),
            (Isa::Portable, 8) => work.run::<Lanes<8>>(),
            (Isa::Portable, _) => work.run::<Lanes<16>>(),
            #[cfg(target_arch = "x86_64")]
            // SAFETY: `Kernel::new` checked that this CPU has AVX2.
            (Isa::Avx2, lanes) => unsafe { x86::avx2(work, lanes) },
            #[cfg(target_arch = "x86_64")]
            // SAFETY: `Kernel::new` checked that this CPU has AVX-512F.
            (Isa::Avx512, lanes) => unsafe { x86::avx512(work, lanes) },
            #[cfg(not(target_arch = "x86_64"))]
            (Isa::Avx2 | Isa::Avx512, _) => unreachable!("Kernel::new checked the instruction set"),
        }
    }
}

/// Work written once over [`Real`]; its `run` must be `#[inline(always)]`, so that each kernel
/// compiles it for its own instruction set.
pub(crate) trait LaneWork {
    fn run<L: Real>(self);
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use super::{LaneWork, Lanes};

    #[target_feature(enable = "avx2")]
    pub(super) fn avx2<W: LaneWork>(work: W, lanes: usize) {
        match lanes {
            4 => work.run::<Lanes<4>>(),
            8 => work.run::<Lanes<8>>(),
            _ => work.run::<Lanes<16>>(),
        }
    }

    #[target_feature(enable = "avx512f")]
    pub(super) fn avx512<W: LaneWork>(work: W, lanes: usize) {
        match lanes {
            4 => work.run::<Lanes<4>>(),
            8 => work.run::<Lanes<8>>(),
            _ => work.run::<Lanes<16>>(),
        }
    }
}
