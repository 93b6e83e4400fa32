//! Which code runs the devices: one at a time, or `N` in lockstep in loops compiled for an
//! instruction set the CPU has, chosen at run time.
//!
//! Every kernel runs the same generic code ([`crate::lanes::Real`]) and, as that code uses only
//! correctly rounded operations, gives the same bits: the choice changes the speed, never a number.
//! A build runs on any x86_64 (SSE2 is the baseline) and compiles on any other architecture, where
//! only the portable kernels exist.

use crate::lanes::Real;
use std::sync::OnceLock;

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
/// (one to four minutes of the optimiser each on this project's machine): the list holds the width
/// measured fastest for each instruction set (docs/performance.md). Their widths differ (4, 8 and
/// 32), so that batch width is tested wherever AVX2 runs; AVX-512F at 8 lanes, which tested it
/// before, cost 76 s of the optimiser per build and ran the same generic code as the other two.
///
/// The AVX-512 kernel is most of the crate's build (5.5 of its 8.4 minutes on 2 cores): a build
/// holds it only where it can run, on a host with AVX-512F, or when `BOUNCEWEAR_ALL_KERNELS` is
/// set (`build.rs`, `cfg(avx512_kernel)`).
#[cfg(all(not(test), avx512_kernel))]
pub const KERNELS: [(Isa, usize); 3] = [(Isa::Portable, 4), (Isa::Avx2, 8), (Isa::Avx512, 32)];
#[cfg(all(not(test), not(avx512_kernel)))]
pub const KERNELS: [(Isa, usize); 2] = [(Isa::Portable, 4), (Isa::Avx2, 8)];

/// The crate's unit tests are a second compilation of it: they hold the portable kernel only,
/// which runs the same generic code. Every kernel of [`KERNELS`] is tested against one device at
/// a time by `model/tests/integration/kernels.rs`, on the library's own build.
#[cfg(test)]
pub const KERNELS: [(Isa, usize); 1] = [(Isa::Portable, 4)];

/// The kernel of this process, once chosen or first used ([`Kernel::active`]).
static CHOSEN: OnceLock<Kernel> = OnceLock::new();

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

    /// The kernel called `name`: `scalar` (one device at a time), or an instruction set of
    /// [`KERNELS`] (`portable`, `avx2`, `avx512`) with its lanes; `None` when this build does not
    /// hold it or this CPU does not run it ([`Kernel::names`] lists those it does).
    pub fn named(name: &str) -> Option<Kernel> {
        Kernel::all().into_iter().find(|k| k.name() == name)
    }

    /// The names of every kernel this CPU runs ([`Kernel::all`]), for [`Kernel::named`].
    pub fn names() -> Vec<&'static str> {
        Kernel::all().into_iter().map(Kernel::name).collect()
    }

    /// `scalar`, or the kernel's instruction set.
    pub fn name(self) -> &'static str {
        if self.lanes == 1 {
            "scalar"
        } else {
            self.isa.as_str()
        }
    }

    /// Makes `kernel` the one every job of this process runs on ([`Kernel::active`]), once,
    /// before the first job: a switch for tests and benchmarks that compare kernels through the
    /// binary, as the choice never changes a number. `Err` with the kernel already in use.
    pub fn choose(kernel: Kernel) -> Result<(), Kernel> {
        CHOSEN.set(kernel).map_err(|_| Kernel::active())
    }

    /// The kernel jobs run on: the one chosen ([`Kernel::choose`]), else [`Kernel::best`].
    pub fn active() -> Kernel {
        *CHOSEN.get_or_init(Kernel::best)
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

    /// This kernel and every other of this CPU with fewer lanes and no wider instruction set
    /// (never [`Kernel::SCALAR`]), widest first: on AVX-512, 32 lanes, then AVX2's 8, then the
    /// portable 4.
    pub fn narrower(self) -> Vec<Kernel> {
        let mut kernels: Vec<Kernel> = Kernel::all()
            .into_iter()
            .filter(|k| k.lanes > 1 && k.lanes <= self.lanes && k.isa.width() <= self.isa.width())
            .collect();
        kernels.sort_by_key(|k| std::cmp::Reverse((k.lanes, k.isa.width())));
        kernels
    }

    pub fn isa(self) -> Isa {
        self.isa
    }

    pub fn lanes(self) -> usize {
        self.lanes
    }

    /// What bounds this kernel from below, for `bench` to time: `rounds` square roots (or,
    /// with `division`, divisions) of each lane of [`FLOOR_CHAINS`] batches, in the kernel's
    /// instruction set and lanes. The batches are independent, so the instructions overlap as
    /// far as the core allows and the time per lane is their throughput, the cost of the
    /// operations the physics cannot do without (docs/performance.md, "The floor"). Returns the
    /// lanes' sum, so that none of it can be left out.
    pub fn floor_work(self, division: bool, rounds: u64) -> f64 {
        let mut sum = 0.0;
        self.run(Floor {
            division,
            rounds,
            sum: &mut sum,
        });
        sum
    }

    /// Runs `work` on this kernel's lanes, compiled for its instruction set.
    pub(crate) fn run<W: LaneWork>(self, work: W) {
        match (self.isa, self.lanes) {
            (_, 1) => scalar::run(work),
            (Isa::Portable, _) => portable_4::run(work),
            #[cfg(all(target_arch = "x86_64", not(test)))]
            // SAFETY: `Kernel::new` checked that this CPU has AVX2.
            (Isa::Avx2, _) => unsafe { avx2_8::run(work) },
            #[cfg(all(avx512_kernel, not(test)))]
            // SAFETY: `Kernel::new` checked that this CPU has AVX-512F.
            (Isa::Avx512, _) => unsafe { avx512_32::run(work) },
            // What this build does not hold.
            #[allow(unreachable_patterns)]
            (Isa::Avx2 | Isa::Avx512, _) => unreachable!("Kernel::new checked KERNELS"),
        }
    }
}

/// Work written once over [`Real`]; its `run` must be `#[inline(always)]`, so that each kernel
/// compiles it for its own instruction set.
pub(crate) trait LaneWork {
    fn run<L: Real>(self);
}

/// Independent batches [`Kernel::floor_work`] runs side by side: enough for the core to start a
/// square root or a division as often as its units allow, rather than wait on the one before.
pub const FLOOR_CHAINS: usize = 8;

struct Floor<'a> {
    division: bool,
    rounds: u64,
    sum: &'a mut f64,
}

impl LaneWork for Floor<'_> {
    fn run<L: Real>(self) {
        // Square roots tend to 1 and divisions of 1.75 swap two values: every lane stays normal.
        // Written out batch by batch: a loop over the batches was vectorised across them, each
        // lane gathered and scattered.
        let mut x: [L; FLOOR_CHAINS] = std::array::from_fn(|i| L::splat(1.5 + i as f64 / 8.0));
        let n = L::splat(1.75);
        if self.division {
            for _ in 0..self.rounds {
                x = [
                    n / x[0],
                    n / x[1],
                    n / x[2],
                    n / x[3],
                    n / x[4],
                    n / x[5],
                    n / x[6],
                    n / x[7],
                ];
            }
        } else {
            for _ in 0..self.rounds {
                x = [
                    x[0].sqrt(),
                    x[1].sqrt(),
                    x[2].sqrt(),
                    x[3].sqrt(),
                    x[4].sqrt(),
                    x[5].sqrt(),
                    x[6].sqrt(),
                    x[7].sqrt(),
                ];
            }
        }
        *self.sum = x
            .iter()
            .flat_map(|x| (0..L::LANES).map(|i| x.lane(i)))
            .sum();
    }
}

/// One kernel: `work` on lanes `$lanes`, compiled for `$feature` (or the build's baseline), in a
/// function that is not inlined and a module of its own. rustc gives each module's functions one
/// codegen unit, so each kernel is optimised on its own and in parallel with the others: in one
/// module the three x86 kernels were one unit, 370 of the crate's 440 s of optimiser time on one
/// core (`-Zllvm-time-trace`, 2-core Zen 4).
macro_rules! kernel {
    ($module:ident, $lanes:ty $(, $feature:literal)?) => {
        mod $module {
            $(#[target_feature(enable = $feature)])?
            #[inline(never)]
            pub(super) fn run<W: super::LaneWork>(work: W) {
                work.run::<$lanes>()
            }
        }
    };
}

kernel!(scalar, f64);
kernel!(portable_4, crate::lanes::Lanes<4>);
#[cfg(all(target_arch = "x86_64", not(test)))]
kernel!(avx2_8, crate::lanes::avx2::Lanes8, "avx2");
#[cfg(all(avx512_kernel, not(test)))]
kernel!(avx512_32, crate::lanes::Lanes<32>, "avx512f");

#[cfg(test)]
mod tests {
    use super::*;

    /// The floor's work gives every kernel's lanes the scalar chains' values.
    #[test]
    fn the_floors_chains_stay_normal_on_every_kernel() {
        for kernel in Kernel::all() {
            for division in [false, true] {
                let scalar = Kernel::SCALAR.floor_work(division, 1001);
                let sum = kernel.floor_work(division, 1001);
                let expected = scalar * kernel.lanes() as f64;
                assert!(sum.is_normal() && scalar > 0.0, "{kernel:?}: {sum}");
                assert!(
                    (sum - expected).abs() <= 1e-12 * expected,
                    "{kernel:?}: {sum} against {expected}"
                );
            }
        }
    }

    /// Every kernel this CPU runs is found by its name, and only those.
    #[test]
    fn a_kernel_is_named_by_its_instruction_set_or_scalar() {
        assert_eq!(Kernel::named("scalar"), Some(Kernel::SCALAR));
        assert_eq!(
            Kernel::named("portable").map(|k| (k.isa(), k.lanes())),
            Some((Isa::Portable, 4))
        );
        for kernel in Kernel::all() {
            assert_eq!(Kernel::named(kernel.name()), Some(kernel));
        }
        assert_eq!(Kernel::names(), ["scalar", "portable"]);
        for unknown in ["", "Scalar", "avx", "sse2", "portable x4"] {
            assert_eq!(Kernel::named(unknown), None, "{unknown}");
        }
    }
}
