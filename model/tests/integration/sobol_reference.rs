//! Sobol' indices against SALib on identical evaluations: `tests/data/sobol_reference.json`
//! (`tools/sobol_reference.py`) holds the Ishigami function on SALib's own samples and SALib's
//! `sobol.analyze` indices; the accumulator, fed the same outputs, gives the same indices to 1e-10.

use bouncewear_model::stats::sobol::SobolAccumulator;
use serde_json::Value;

#[test]
fn the_indices_are_salibs_on_the_same_evaluations() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/data/sobol_reference.json"
    );
    let reference: Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let inputs = reference["inputs"].as_u64().unwrap() as usize;
    let numbers = |key: &str| -> Vec<f64> {
        reference[key]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect()
    };
    let outputs = numbers("outputs");
    // SALib's order, per base sample: A, AB_1 .. AB_k, B.
    let mut sobol = SobolAccumulator::new(inputs, 0.0);
    for block in outputs.chunks_exact(inputs + 2) {
        sobol.push(block[0], block[inputs + 1], &block[1..=inputs]);
    }
    assert_eq!(sobol.count(), reference["base_samples"].as_u64().unwrap());
    let indices = sobol.indices();
    for (i, (first, total)) in numbers("first")
        .into_iter()
        .zip(numbers("total"))
        .enumerate()
    {
        for (what, got, want) in [
            ("first", indices[i].first.value, first),
            ("total", indices[i].total.value, total),
        ] {
            assert!(
                (got - want).abs() <= 1e-10 * want.abs().max(1e-2),
                "x{} {what}: {got} against SALib's {want}",
                i + 1
            );
        }
    }
}
