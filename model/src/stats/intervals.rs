//! The two interval ingredients: Student's t 0.975 quantile (batch-means intervals from few groups)
//! and the Wilson score interval (proportions, honest near 0 and 1).

/// The standard normal 0.975 quantile, `Phi^-1(0.975)`.
pub const Z_975: f64 = 1.959_963_984_540_054;

/// `t_{0.975, df}` for `df = 1 ..= 30`, rounded to the nearest f64 (computed from the
/// regularised incomplete beta function at 40 digits).
const T_975: [f64; 30] = [
    12.706204736174705,
    4.302652729749464,
    3.1824463052837095,
    2.7764451051977943,
    2.5705818356363155,
    2.44691185114497,
    2.3646242515927853,
    2.3060041352041667,
    2.2621571627982053,
    2.228138851986275,
    2.2009851600916397,
    2.178812829667229,
    2.1603686564627926,
    2.144786687917804,
    2.1314495455597755,
    2.1199052992212546,
    2.109815577833317,
    2.1009220402410387,
    2.0930240544083096,
    2.085963447265865,
    2.0796138447276804,
    2.0738730679040263,
    2.0686576104190486,
    2.063898561628026,
    2.0595385527532977,
    2.055529438642873,
    2.0518305164802855,
    2.048407141795245,
    2.0452296421327043,
    2.042272456301238,
];

/// The 0.975 quantile of Student's t with `df` degrees of freedom, the factor of a two-sided 95 %
/// interval from `df + 1` batches.
///
/// `df <= 30`: the exact table. Above, the Cornish-Fisher expansion in `1/df` around
/// `z = Z_975` (Fisher 1925; Abramowitz & Stegun 26.7.5):
/// `t = z + g1/df + g2/df^2 + g3/df^3 + g4/df^4` with
/// `g1 = (z^3 + z)/4`, `g2 = (5z^5 + 16z^3 + 3z)/96`, `g3 = (3z^7 + 19z^5 + 17z^3 - 15z)/384`,
/// `g4 = (79z^9 + 776z^7 + 1482z^5 - 1920z^3 - 945z)/92160`; its relative error is below
/// `1.3e-8` at `df = 31` and falls as `df^-5`. `df = 0` gives `+inf` (no batch spread to scale).
pub fn student_t_975(df: u64) -> f64 {
    match df {
        0 => f64::INFINITY,
        1..=30 => T_975[df as usize - 1],
        _ => {
            let z = Z_975;
            let z2 = z * z;
            let g1 = (z2 + 1.0) * z / 4.0;
            let g2 = ((5.0 * z2 + 16.0) * z2 + 3.0) * z / 96.0;
            let g3 = (((3.0 * z2 + 19.0) * z2 + 17.0) * z2 - 15.0) * z / 384.0;
            let g4 =
                ((((79.0 * z2 + 776.0) * z2 + 1482.0) * z2 - 1920.0) * z2 - 945.0) * z / 92160.0;
            let v = 1.0 / df as f64;
            z + v * (g1 + v * (g2 + v * (g3 + v * g4)))
        }
    }
}

/// Wilson score interval for a proportion `p` observed over an (effective) sample size `n_eff`,
/// at normal quantile `z` (use [`Z_975`] for 95 %):
/// `centre = (p + z^2/(2n)) / (1 + z^2/n)`,
/// `half = z / (1 + z^2/n) * sqrt(p(1 - p)/n + z^2/(4n^2))`, result `[centre - half, centre + half]`
/// clipped to `[0, 1]` and widened to hold `p` against rounding. Unlike the Wald interval it stays
/// inside `[0, 1]`, contains `p`, and is not
/// empty at `p = 0` or `1` (`[0, z^2/(n + z^2)]` at `p = 0`). `n_eff` may be fractional (a design
/// effect applied); `n_eff <= 0` carries no information and gives `[0, 1]`.
pub fn wilson_interval(p: f64, n_eff: f64, z: f64) -> [f64; 2] {
    if n_eff.is_nan() || n_eff <= 0.0 {
        return [0.0, 1.0];
    }
    let z2n = z * z / n_eff;
    let centre = (p + z2n / 2.0) / (1.0 + z2n);
    let half = z / (1.0 + z2n) * (p * (1.0 - p) / n_eff + z2n / (4.0 * n_eff)).sqrt();
    // The interval holds `p` exactly: at p = 0 rounding would leave its lower end at 1e-18.
    [
        (centre - half).max(0.0).min(p),
        (centre + half).min(1.0).max(p),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn t_quantiles_match_known_values() {
        let known = [
            (1, 12.706204736),
            (2, 4.302652730),
            (5, 2.570581836),
            (10, 2.228138852),
            (30, 2.042272456),
            (31, 2.039513446),
            (40, 2.021075390),
            (50, 2.008559112),
            (100, 1.983971519),
            (1000, 1.962339081),
            (10000, 1.960201240),
        ];
        for (df, t) in known {
            assert_relative_eq!(student_t_975(df), t, max_relative = 1e-6);
        }
        assert_relative_eq!(student_t_975(u64::MAX), Z_975, max_relative = 1e-15);
        assert_eq!(student_t_975(0), f64::INFINITY);
    }

    #[test]
    fn t_quantiles_decrease_towards_z() {
        let t: Vec<f64> = (1..=200).map(student_t_975).collect();
        assert!(t.windows(2).all(|w| w[0] > w[1]));
        assert!(t.iter().all(|&t| t > Z_975));
    }

    #[test]
    fn wilson_matches_hand_values() {
        let cases = [
            (
                0.5,
                100.0,
                [0.403_831_530_365_995_6, 0.596_168_469_634_004_4],
            ),
            (0.0, 10.0, [0.0, 0.277_532_799_862_889_2]),
            (1.0, 10.0, [0.722_467_200_137_110_8, 1.0]),
            (
                0.2,
                50.0,
                [0.112_437_500_157_761_1, 0.330_371_059_322_254_1],
            ),
            (
                0.01,
                1000.0,
                [0.005_440_754_445_529_249, 0.018_309_468_870_314_77],
            ),
            (
                0.3,
                7.5,
                [0.092_572_954_573_824_14, 0.642_910_809_249_744_3],
            ),
        ];
        for (p, n, [lo, hi]) in cases {
            let [l, h] = wilson_interval(p, n, Z_975);
            assert!((l - lo).abs() <= 1e-14, "{p} {n}: {l} vs {lo}");
            assert!((h - hi).abs() <= 1e-14, "{p} {n}: {h} vs {hi}");
        }
        assert_eq!(wilson_interval(0.3, 0.0, Z_975), [0.0, 1.0]);
    }
}
