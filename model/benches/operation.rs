//! One make operation at each fidelity, and one restitution solve.
//!
//! `cargo bench -p bouncewear-model --bench operation`

use bouncewear_model::restitution::{ELASTIC_SCALED_SPEED, restitution_scaled};
use bouncewear_model::{Fidelity, Needs, Operation, Scenario};
use divan::{Bencher, black_box};

fn main() {
    divan::main();
}

fn operation(scenario: &str, fidelity: Fidelity) -> Operation {
    Operation::nominal(&Scenario::from_json(scenario).unwrap(), fidelity)
}

const MECHANICAL: &str = "{}";
const ARCING: &str = r#"{"circuit":{"supply_voltage_v":48,"current_a":15}}"#;

#[divan::bench(args = [Fidelity::Exact, Fidelity::ClosedForm])]
fn mechanical_operation_7_bounces(bencher: Bencher, fidelity: Fidelity) {
    let op = operation(MECHANICAL, fidelity);
    bencher.bench_local(|| black_box(&op).run(black_box(7.7e-3), black_box(2e8), Needs::ALL, None));
}

#[divan::bench(args = [Fidelity::Exact, Fidelity::ClosedForm])]
fn arcing_operation_48v_15a(bencher: Bencher, fidelity: Fidelity) {
    let op = operation(ARCING, fidelity);
    bencher.bench_local(|| black_box(&op).run(black_box(7.7e-3), black_box(2e8), Needs::ALL, None));
}

/// Skipping the first-impact work (peak force, duration) when no metric asks for it.
#[divan::bench]
fn mechanical_operation_without_impact_phase(bencher: Bencher) {
    let op = operation(MECHANICAL, Fidelity::Exact);
    bencher.bench_local(|| {
        black_box(&op).run(
            black_box(7.7e-3),
            black_box(2e8),
            Needs { impact: false },
            None,
        )
    });
}

/// One solve of eq. 7, averaged over 1024 scaled speeds spread across the inelastic range.
#[divan::bench(counter = divan::counter::ItemsCount::new(1024usize))]
fn restitution_solve(bencher: Bencher) {
    let speeds: Vec<f64> = (0..1024)
        .map(|i| ELASTIC_SCALED_SPEED * (f64::from(i) + 0.5) / 1024.0)
        .collect();
    bencher.bench_local(|| {
        let mut sum = 0.0;
        for &eps0 in black_box(&speeds) {
            sum += restitution_scaled(eps0);
        }
        sum
    });
}
