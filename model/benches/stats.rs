//! The statistics of one bin as the engine gives them, on one thread.
//!
//! `accumulate`: one bin's values into its accumulators, as the engine buffers them: 11 metrics of
//! 8 devices x 50 operations (the reference jobs' bins at 8 lanes), pushed one by one in the order
//! of one device at a time, or a metric's column at a time with `Accumulator::push_batch`. Both
//! give the same accumulators to the bit; divan reports the time per value.
//!
//! `summary`: the summary of one (metric, bin) of the reference jobs, 32 groups of 3100 values
//! (2000 devices x 50 operations) spread over about 9 binades, with an exceedance limit.
//!
//! `tails`: one group's bin of the 10^7-operation scale-out job (`tools/scaleout_bench.py`: 1000
//! devices x 10,000 operations, so groups of 31 devices, one 32-lane batch with a spare lane, and
//! 1000 operations a bin at the default 10 bins) into the exact tails a service run keeps (25
//! values at each end), values drifting down 30 % through the bin as a wearing contact's kappa
//! does, or scattered without a drift; divan reports the time per value.
//!
//! `filling_tails`: the lists of a 100 x 100 job's accumulators (32 groups of about 3 devices, 10
//! bins: about 31 values each), none full: 31 values one by one into a list keeping 25 at each
//! end; divan reports the time per list.
//!
//! `cargo bench -p bouncewear-model --bench stats`

use bouncewear_model::lanes::Lanes;
use bouncewear_model::stats::{Accumulator, Tails, summarize};
use divan::{Bencher, black_box, counter::ItemsCount};

fn main() {
    divan::main();
}

const METRICS: usize = 11;
const VALUES: usize = 8 * 50;

/// splitmix64, uniform on [0, 1).
fn uniforms(seed: u64) -> impl Iterator<Item = f64> {
    let mut state = seed;
    std::iter::repeat_with(move || {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        (z ^ (z >> 31)) as f64 / 2f64.powi(64)
    })
}

/// Metric `m`'s values, shaped like the engine's: continuous and spread over a decade, small
/// integers (bounce counts), or zero for about half the operations (no arc).
fn column(m: usize) -> Vec<f64> {
    uniforms(m as u64 + 1)
        .take(VALUES)
        .map(|u| match m % 3 {
            0 => 1e-3 * (1.0 + 9.0 * u),
            1 => (1.0 + 7.0 * u).floor(),
            _ if u < 0.5 => 0.0,
            _ => 0.02 * u,
        })
        .collect()
}

/// One column per metric, and the same values row by row (device-major, a row per operation).
fn bin() -> (Vec<f64>, Vec<f64>) {
    let columns: Vec<f64> = (0..METRICS).flat_map(column).collect();
    let rows = (0..VALUES * METRICS)
        .map(|i| columns[(i % METRICS) * VALUES + i / METRICS])
        .collect();
    (columns, rows)
}

fn accumulators() -> Vec<Accumulator> {
    (0..METRICS)
        .map(|m| Accumulator::new((m % 2 == 0).then_some(5e-3)))
        .collect()
}

#[divan::bench]
fn accumulate_one_by_one(bencher: Bencher) {
    let (_, rows) = bin();
    let mut accumulators = accumulators();
    bencher
        .counter(ItemsCount::new(rows.len()))
        .bench_local(|| {
            for values in black_box(&rows).chunks_exact(METRICS) {
                for (accumulator, &value) in accumulators.iter_mut().zip(values) {
                    accumulator.push(value);
                }
            }
        });
}

#[divan::bench]
fn accumulate_push_batch(bencher: Bencher) {
    let (columns, _) = bin();
    let mut accumulators = accumulators();
    bencher
        .counter(ItemsCount::new(columns.len()))
        .bench_local(|| {
            for (accumulator, values) in accumulators
                .iter_mut()
                .zip(black_box(&columns).chunks_exact(VALUES))
            {
                accumulator.push_batch(values);
            }
        });
}

#[divan::bench(sample_count = 50)]
fn summary_of_32_groups(bencher: Bencher) {
    let groups: Vec<Accumulator> = (0..32)
        .map(|g| {
            let mut group = Accumulator::new(Some(3e-3));
            // Log-uniform over e^-3 .. e^3 around 2e-3.
            uniforms(g + 100)
                .take(3100)
                .for_each(|u| group.push(2e-3 * (6.0 * u - 3.0).exp()));
            group
        })
        .collect();
    bencher.bench_local(|| summarize(black_box(&groups), 1));
}

const TAIL_DEVICES: usize = 31;
const TAIL_OPERATIONS: usize = 1000;

/// A bin's values as the engine's batch gives them, one 32-lane column an operation, each lane a
/// device (the last lane spare).
fn tail_batches(drift: f64) -> Vec<Lanes<32>> {
    let mut noise = uniforms(7);
    let level: Vec<f64> = uniforms(3).take(32).map(|u| 0.5 + u).collect();
    (0..TAIL_OPERATIONS)
        .map(|op| {
            let wear = 1.0 - drift * op as f64 / TAIL_OPERATIONS as f64;
            Lanes(std::array::from_fn(|k| {
                level[k] * wear * (0.95 + 0.1 * noise.next().unwrap())
            }))
        })
        .collect()
}

#[divan::bench(args = [0.0, 0.3], sample_count = 50)]
fn tails(bencher: Bencher, drift: f64) {
    let batches = tail_batches(drift);
    bencher
        .counter(ItemsCount::new(TAIL_DEVICES * TAIL_OPERATIONS))
        .bench_local(|| {
            let mut tails = Tails::new(25);
            for column in black_box(&batches) {
                tails.push_lanes(column, 0..TAIL_DEVICES);
            }
            tails
        });
}

/// Values a list of a small job's accumulator takes, fewer than fill its ends.
const FILLING_VALUES: usize = 31;

#[divan::bench(sample_count = 100)]
fn filling_tails(bencher: Bencher) {
    let values: Vec<f64> = uniforms(11).take(FILLING_VALUES).map(|u| 0.5 + u).collect();
    bencher.counter(ItemsCount::new(1usize)).bench_local(|| {
        let mut tails = Tails::new(25);
        for &x in black_box(&values) {
            tails.push(x);
        }
        tails
    });
}
