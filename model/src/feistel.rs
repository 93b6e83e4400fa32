//! Keyed permutations by a balanced Feistel network: a block of two halves, each round swapping
//! them and mixing one into the other through a round function, `(l, r) -> (r, l ^ F(round, r))`.
//! That is a bijection whatever `F` is, undone by running the rounds backwards; four rounds of a
//! pseudorandom `F` make a strong pseudorandom permutation (Luby and Rackoff, *SIAM J. Comput.*
//! 17, 1988). Two users: the service's listing cursors (96 bits, SHA-256 rounds) and the Latin
//! hypercube's strata ([`Permutation`]: of `0..n` for any `n`, its value at one point at a time).

/// The block `(left, right)` through `rounds` rounds of `round` (its values cut to `half_bits`).
/// `half_bits` is at most 63; `block` holds `2 half_bits` bits.
pub fn encrypt(block: u128, half_bits: u32, rounds: u8, round: impl Fn(u8, u64) -> u64) -> u128 {
    let mask = half_mask(half_bits);
    let (mut left, mut right) = split(block, half_bits);
    for r in 0..rounds {
        (left, right) = (right, left ^ (round(r, right) & mask));
    }
    join(left, right, half_bits)
}

/// The block [`encrypt`] took to `block` with the same rounds.
pub fn decrypt(block: u128, half_bits: u32, rounds: u8, round: impl Fn(u8, u64) -> u64) -> u128 {
    let mask = half_mask(half_bits);
    let (mut left, mut right) = split(block, half_bits);
    for r in (0..rounds).rev() {
        (left, right) = (right ^ (round(r, left) & mask), left);
    }
    join(left, right, half_bits)
}

fn half_mask(half_bits: u32) -> u64 {
    assert!(half_bits < 64, "a half holds at most 63 bits");
    (1 << half_bits) - 1
}

fn split(block: u128, half_bits: u32) -> (u64, u64) {
    let mask = u128::from(half_mask(half_bits));
    // Both halves are masked to `half_bits`: the casts keep exactly those bits.
    (((block >> half_bits) & mask) as u64, (block & mask) as u64)
}

fn join(left: u64, right: u64, half_bits: u32) -> u128 {
    (u128::from(left) << half_bits) | u128::from(right)
}

/// Rounds of a [`Permutation`]: four make a pseudorandom permutation of a pseudorandom round
/// function; two more are margin for a round function of one multiplication.
pub const PERMUTATION_ROUNDS: usize = 6;

/// A keyed pseudorandom permutation of `0..size` for `size` up to 2^32, evaluated one point at a
/// time, in no memory: a Feistel network over the smallest block of an even number of bits that
/// holds `size` values (fewer than `4 size`), applied again while the value lies at or beyond
/// `size` ("cycle walking": the walk from a point of `0..size` stays on its cycle of the block's
/// permutation until it comes back into `0..size`, so each point of `0..size` gets another of
/// them, and no two the same; fewer than four steps on average). Round `r` adds key `r` to the
/// half and keeps the top bits of its product with odd multiplier `r` (multiply-shift hashing).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Permutation {
    size: u64,
    half_bits: u32,
    keys: [(u64, u64); PERMUTATION_ROUNDS],
}

impl Permutation {
    /// The permutation of `0..size` that `keys` (an addend and a multiplier for each round, the
    /// multiplier made odd) pick.
    ///
    /// # Panics
    /// If `size` is above 2^32.
    pub fn new(size: u64, keys: [(u64, u64); PERMUTATION_ROUNDS]) -> Self {
        assert!(size <= 1 << 32, "a permutation of at most 2^32 points");
        // The smallest even number of bits whose block holds `size` values.
        let bits = u64::BITS - size.saturating_sub(1).leading_zeros();
        Self {
            size,
            half_bits: bits.div_ceil(2),
            keys: keys.map(|(addend, multiplier)| (addend, multiplier | 1)),
        }
    }

    /// The number of points permuted.
    pub fn size(&self) -> u64 {
        self.size
    }

    /// The point `x` goes to.
    ///
    /// # Panics
    /// If `x` is not below [`Self::size`].
    pub fn apply(&self, x: u64) -> u64 {
        assert!(x < self.size, "point {x} of a permutation of {}", self.size);
        let shift = 64 - self.half_bits;
        let round = |r: u8, half: u64| {
            let (addend, multiplier) = self.keys[usize::from(r)];
            // `checked_shr`: a block of one point has halves of no bits, whose rounds add 0.
            (half.wrapping_add(addend).wrapping_mul(multiplier))
                .checked_shr(shift)
                .unwrap_or(0)
        };
        let mut y = x;
        loop {
            y = encrypt(
                u128::from(y),
                self.half_bits,
                PERMUTATION_ROUNDS as u8,
                round,
            ) as u64;
            if y < self.size {
                return y;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn keys(seed: u64) -> [(u64, u64); PERMUTATION_ROUNDS] {
        // SplitMix64's sequence: keys without structure, from a test's seed.
        let mut state = seed;
        let mut next = || {
            state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = state;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            z ^ (z >> 31)
        };
        std::array::from_fn(|_| (next(), next()))
    }

    #[test]
    fn every_size_to_a_few_thousand_is_permuted_whole() {
        for size in (0..=1100).chain([4095, 4096, 4097, 65_535, 65_536, 65_537, 99_991]) {
            let permutation = Permutation::new(size, keys(size));
            let mut seen = vec![false; size as usize];
            for x in 0..size {
                let y = permutation.apply(x);
                assert!(y < size && !seen[y as usize], "size {size}: {x} -> {y}");
                seen[y as usize] = true;
            }
        }
    }

    #[test]
    fn a_large_permutation_is_whole_and_its_walks_short() {
        // Just above a power of four: the block holds nearly four times the points.
        let size = (1 << 22) + 1;
        let permutation = Permutation::new(size, keys(7));
        let mut seen = vec![0u64; (size as usize).div_ceil(64)];
        for x in 0..size {
            let y = permutation.apply(x) as usize;
            assert_eq!(seen[y / 64] >> (y % 64) & 1, 0, "{x} -> {y} twice");
            seen[y / 64] |= 1 << (y % 64);
        }
        assert_eq!(
            Permutation::new(1 << 32, keys(1)).apply((1 << 32) - 1) >> 32,
            0
        );
    }

    /// The points of a contiguous range of `0..n` (a group of devices) land all over `0..n`: the
    /// mean of each of 32 ranges' images is within its sampling spread of the middle (chi-square
    /// over the ranges, 31 degrees of freedom), and two keys' permutations are uncorrelated
    /// (Spearman's rho within four standard errors, `1 / sqrt(n - 1)`), for several keys and sizes.
    #[test]
    fn ranges_spread_over_the_whole_and_keys_do_not_correlate() {
        for (seed, n) in [(1, 100_000u64), (2, 65_536), (3, 262_145), (4, 1000)] {
            let (p, q) = (
                Permutation::new(n, keys(seed)),
                Permutation::new(n, keys(!seed)),
            );
            let m = n / 32;
            let (mid, var) = ((n - 1) as f64 / 2.0, (n * n - 1) as f64 / 12.0);
            let chi2: f64 = (0..32)
                .map(|g| {
                    let mean =
                        (g * m..(g + 1) * m).map(|x| p.apply(x) as f64).sum::<f64>() / m as f64;
                    // A sample without replacement of `m` of `n` points: the finite population's
                    // correction of the mean's variance.
                    let se2 = var / m as f64 * (n - m) as f64 / (n - 1) as f64;
                    (mean - mid).powi(2) / se2
                })
                .sum();
            // 31 degrees of freedom: the 0.9999 quantile is about 68.
            assert!(chi2 < 68.0, "n {n}: chi-square {chi2} over 32 ranges");
            let d2: f64 = (0..n)
                .map(|x| (p.apply(x) as f64 - q.apply(x) as f64).powi(2))
                .sum();
            let nf = n as f64;
            let rho = 1.0 - 6.0 * d2 / (nf * (nf * nf - 1.0));
            assert!(rho.abs() < 4.0 / (nf - 1.0).sqrt(), "n {n}: rho {rho}");
        }
    }

    proptest! {
        #[test]
        fn decrypt_undoes_encrypt(block in any::<u128>(), half_bits in 0u32..=63, rounds in 0u8..12) {
            let block = block & ((1u128 << (2 * half_bits)) - 1);
            let round = |r: u8, half: u64| half.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ u64::from(r);
            let sealed = encrypt(block, half_bits, rounds, round);
            prop_assert!(sealed >> (2 * half_bits) == 0);
            prop_assert_eq!(decrypt(sealed, half_bits, rounds, round), block);
        }
    }
}
