//! Listing cursors that name a place in a key's list and nothing more. A page of jobs or schedules
//! ends at a row's sequence number, which counts every key's rows: given as it is, the gap between
//! two of one key's cursors would say how many jobs or schedules other keys made meanwhile. The
//! number is sealed instead, with a secret every instance on the database shares (drawn once, by
//! the database's migration): a keyed permutation of 96 bits, the number and 32 zero bits, so that
//! a cursor this server did not give opens to nothing (but for one in 2^32).

use bouncewear_model::feistel::{self, Halves};
use sha2::{Digest, Sha256};

/// Rounds of the Feistel network: four make a strong pseudorandom permutation (Luby and
/// Rackoff); the rest is margin, at a hash a round. Even, with equal halves: the classic form
/// that swaps the halves every round, as cursors were sealed before it was shared.
const ROUNDS: u8 = 8;
/// The block's two halves of 48 bits.
const HALVES: Halves = Halves::equal(96);
/// Hex digits of a cursor: 96 bits.
const DIGITS: usize = 24;

/// The key that seals and opens cursors, derived from the database's secret.
#[derive(Clone)]
pub struct CursorKey([u8; 32]);

impl std::fmt::Debug for CursorKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("CursorKey(..)")
    }
}

impl CursorKey {
    /// The key of a database's stored secret.
    pub fn from_secret(secret: &str) -> Self {
        Self(Sha256::digest(secret.as_bytes()).into())
    }

    /// The key of one list's cursors (`jobs`, `schedules`), so that a cursor of one list opens in
    /// no other.
    pub fn of_list(&self, list: &str) -> Self {
        Self(
            Sha256::new()
                .chain_update(self.0)
                .chain_update(list.as_bytes())
                .finalize()
                .into(),
        )
    }

    /// The cursor of the place after row `seq`: 24 lowercase hex digits.
    pub fn seal(&self, seq: i64) -> String {
        // The block: the number's 63 bits, then 32 zero bits that opening checks.
        let block = u128::from(u64::try_from(seq).unwrap_or(0)) << 32;
        let sealed = feistel::encrypt(block, HALVES, ROUNDS, |r, half| self.round(r, half));
        format!("{sealed:0width$x}", width = DIGITS)
    }

    /// The row a cursor [`Self::seal`] gave stands after; `None` for anything else.
    pub fn open(&self, cursor: &str) -> Option<i64> {
        let digits = cursor.len() == DIGITS
            && cursor
                .bytes()
                .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b));
        let block = digits.then(|| u128::from_str_radix(cursor, 16).ok())??;
        let block = feistel::decrypt(block, HALVES, ROUNDS, |r, half| self.round(r, half));
        let sealed_zeros = block & u128::from(u32::MAX) == 0;
        let seq = i64::try_from(block >> 32).ok()?;
        (sealed_zeros && seq > 0).then_some(seq)
    }

    /// The round function: 48 bits of SHA-256 over the key, the round and the half.
    fn round(&self, round: u8, half: u64) -> u64 {
        let digest = Sha256::new()
            .chain_update(self.0)
            .chain_update([round])
            .chain_update(half.to_le_bytes())
            .finalize();
        let mut bytes = [0; 8];
        bytes[..6].copy_from_slice(&digest[..6]);
        u64::from_le_bytes(bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn key() -> CursorKey {
        CursorKey::from_secret("0123456789abcdef0123456789abcdef")
    }

    proptest! {
        #[test]
        fn every_row_number_opens_to_itself(seq in 1..=i64::MAX) {
            let cursor = key().seal(seq);
            prop_assert_eq!(cursor.len(), DIGITS);
            prop_assert_eq!(key().open(&cursor), Some(seq));
        }

        #[test]
        fn another_databases_cursor_opens_to_nothing(seq in 1..=i64::MAX) {
            let other = CursorKey::from_secret("another database's secret");
            prop_assert_eq!(other.open(&key().seal(seq)), None);
        }

        #[test]
        fn another_lists_cursor_opens_to_nothing(seq in 1..=i64::MAX) {
            let (jobs, schedules) = (key().of_list("jobs"), key().of_list("schedules"));
            prop_assert_eq!(schedules.open(&jobs.seal(seq)), None);
            prop_assert_eq!(jobs.open(&jobs.seal(seq)), Some(seq));
        }
    }

    #[test]
    fn neighbouring_rows_share_no_visible_order() {
        // Consecutive numbers give cursors that differ in about half their bits, and sort in no
        // relation to the numbers: a gap between two cursors says nothing of the rows between.
        let cursors: Vec<u128> = (1..=2000)
            .map(|seq| u128::from_str_radix(&key().seal(seq), 16).unwrap())
            .collect();
        let differing: u32 = cursors
            .windows(2)
            .map(|pair| (pair[0] ^ pair[1]).count_ones())
            .sum();
        let mean = f64::from(differing) / 1999.0;
        assert!((44.0..=52.0).contains(&mean), "{mean} of 96 bits differ");
        let ascending = cursors.windows(2).filter(|p| p[0] < p[1]).count();
        assert!(
            (900..=1100).contains(&ascending),
            "{ascending} of 1999 ascend"
        );
    }

    #[test]
    fn what_no_server_gave_opens_to_nothing() {
        let key = key();
        let sealed = key.seal(42);
        for cursor in [
            "",
            "42",
            "0",
            &sealed[1..],
            &format!("{sealed}0"),
            &sealed.to_uppercase(),
            &format!("+{}", &sealed[1..]),
            "zzzzzzzzzzzzzzzzzzzzzzzz",
        ] {
            assert_eq!(key.open(cursor), None, "{cursor}");
        }
        // Of 20,000 made-up cursors, none opens: each would with a chance of one in 2^32.
        let forged = (0..20_000u64)
            .filter(|n| {
                key.open(&format!("{:024x}", u128::from(*n) * 0x9e37_79b9_7f4a_7c15))
                    .is_some()
            })
            .count();
        assert_eq!(forged, 0);
    }
}
