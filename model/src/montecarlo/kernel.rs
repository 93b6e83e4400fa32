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

    /// Bits per vector register.
    fn width(self) -> u32 {
        match self {
            Isa::Portable => 128,
            Isa::Avx2 => 256,
            Isa::Avx512 => 512,
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

/// The lockstep kernels a build holds: instruction set and devices per batch. Each is a full copy
/// of the operation and the engine loop, optimised on its own, so every entry costs build time
/// (about a minute each on this project's machine): the list holds the width measured fastest for
/// each instruction set (docs/performance.md), and a second AVX-512 width, so that batch width is
/// tested on this project's machine.
pub const KERNELS: [(Isa, usize); 4] = [
    (Isa::Portable, 4),
    (Isa::Avx2, 8),
    (Isa::Avx512, 8),
    (Isa::Avx512, 32),
];

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

    /// The kernel, if this CPU runs its instruction set and the build holds it ([`KERNELS`]).
    /// One lane is [`Kernel::SCALAR`] whatever the instruction set.
    pub fn new(isa: Isa, lanes: usize) -> Option<Kernel> {
        if lanes == 1 {
            return Some(Kernel::SCALAR);
        }
        (isa.available() && KERNELS.contains(&(isa, lanes))).then_some(Kernel { isa, lanes })
    }

    /// The fastest kernel on this CPU, as measured (docs/performance.md): the widest instruction
    /// set's widest batch.
    pub fn best() -> Kernel {
        Kernel::all()
            .into_iter()
            .max_by_key(|k| (k.isa.width(), k.lanes))
            .unwrap_or(Kernel::SCALAR)
    }

    /// Every kernel this CPU runs, [`Kernel::SCALAR`] first.
    pub fn all() -> Vec<Kernel> {
        std::iter::once(Kernel::SCALAR)
            .chain(
                KERNELS
                    .into_iter()
                    .filter_map(|(isa, lanes)| Kernel::new(isa, lanes)),
            )
            .collect()
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
            (_, 1) => portable::<W, f64>(work),
            (Isa::Portable, _) => portable::<W, Lanes<4>>(work),
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

/// `work` on lanes `L` in the build's baseline instruction set, optimised on its own.
#[inline(never)]
fn portable<W: LaneWork, L: Real>(work: W) {
    work.run::<L>()
}

/// Work written once over [`Real`]; its `run` must be `#[inline(always)]`, so that each kernel
/// compiles it for its own instruction set.
pub(crate) trait LaneWork {
    fn run<L: Real>(self);
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    //! One function per instruction set and lane count: each is optimised on its own (one
    //! function holding every width took the optimiser several times as long) and in parallel.
    use super::{LaneWork, Lanes, Real};

    #[target_feature(enable = "avx2")]
    pub(super) fn avx2<W: LaneWork>(work: W, lanes: usize) {
        debug_assert_eq!(lanes, 8, "KERNELS holds AVX2 with 8 lanes");
        avx2_lanes::<W, 8>(work)
    }

    #[target_feature(enable = "avx2")]
    #[inline(never)]
    fn avx2_lanes<W: LaneWork, const N: usize>(work: W)
    where
        Lanes<N>: Real,
    {
        work.run::<Lanes<N>>()
    }

    #[target_feature(enable = "avx512f")]
    pub(super) fn avx512<W: LaneWork>(work: W, lanes: usize) {
        match lanes {
            8 => avx512_lanes::<W, 8>(work),
            _ => avx512_lanes::<W, 32>(work),
        }
    }

    #[target_feature(enable = "avx512f")]
    #[inline(never)]
    fn avx512_lanes<W: LaneWork, const N: usize>(work: W)
    where
        Lanes<N>: Real,
    {
        work.run::<Lanes<N>>()
    }
}
