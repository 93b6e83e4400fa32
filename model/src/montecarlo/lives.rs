//! Device lives of a job with failure criteria, kept so that any job size fits: every life counted
//! exactly by its whole number of operations ([`GroupLives::counts`], at most one entry per
//! distinct life however many devices share it), and each device's own life listed only as far as
//! its holder asks ([`GroupLives::keep_listed_below`]). The life analysis reads the counts, so
//! dropping listed devices never changes it.

use crate::life::Lives;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// When one device failed (or that it survived the test: censored at the last operation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct DeviceLife {
    pub device: u64,
    /// Operations run up to and including the failing one (all of them when censored).
    pub operations_to_failure: u64,
    pub censored: bool,
}

/// The lives of one group of devices (or of several, merged).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct GroupLives {
    /// Devices by life in operations: `[failed, censored]` at each distinct life.
    pub counts: BTreeMap<u64, [u64; 2]>,
    /// Each device's life, in device order, for the devices still listed.
    pub listed: Vec<DeviceLife>,
}

impl GroupLives {
    /// Counts a device's life, and lists it if it is numbered below `listed_below`. Devices come
    /// in ascending order.
    pub fn record(&mut self, life: DeviceLife, listed_below: u64) {
        let [failed, censored] = self.counts.entry(life.operations_to_failure).or_default();
        if life.censored {
            *censored += 1;
        } else {
            *failed += 1;
        }
        if life.device < listed_below {
            self.listed.push(life);
        }
    }

    /// Adds the lives of the groups after this one.
    pub fn merge(&mut self, other: &GroupLives) {
        for (operations, [failed, censored]) in &other.counts {
            let mine = self.counts.entry(*operations).or_default();
            mine[0] += failed;
            mine[1] += censored;
        }
        self.listed.extend_from_slice(&other.listed);
    }

    /// Keeps listing only the devices numbered below `device`; the counts keep every device.
    pub fn keep_listed_below(&mut self, device: u64) {
        self.listed.retain(|life| life.device < device);
    }

    /// Devices counted.
    pub fn devices(&self) -> u64 {
        self.counts.values().map(|[f, c]| f + c).sum()
    }

    /// The counts as [`Lives`], for the life analysis.
    pub fn lives(&self) -> Lives {
        Lives::from_counts(self.counts.iter().map(|(&ops, &[f, c])| (ops, f, c)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn life(device: u64, operations_to_failure: u64, censored: bool) -> DeviceLife {
        DeviceLife {
            device,
            operations_to_failure,
            censored,
        }
    }

    proptest! {
        /// However the devices are split into groups and however many are listed (a group
        /// trimmed after recording, or recording only those listed), the merged counts are those
        /// of all devices and the listing is a prefix in device order.
        #[test]
        fn merged_groups_count_every_device(
            lives in prop::collection::vec((1u64..30, any::<bool>()), 0..200),
            cut in 0usize..200,
            listed in 0u64..250,
        ) {
            let all: Vec<DeviceLife> = lives
                .iter()
                .enumerate()
                .map(|(d, &(ops, censored))| life(d as u64, ops, censored))
                .collect();
            let cut = cut.min(all.len());
            let (mut first, mut second, mut whole) =
                (GroupLives::default(), GroupLives::default(), GroupLives::default());
            all[..cut].iter().for_each(|&l| first.record(l, u64::MAX));
            all[cut..].iter().for_each(|&l| second.record(l, listed));
            all.iter().for_each(|&l| whole.record(l, u64::MAX));
            first.keep_listed_below(listed);
            first.merge(&second);
            prop_assert_eq!(&first.counts, &whole.counts);
            prop_assert_eq!(first.devices(), all.len() as u64);
            let expected: Vec<DeviceLife> =
                all.iter().copied().filter(|l| l.device < listed).collect();
            prop_assert_eq!(&first.listed, &expected);
            let pairs: Vec<(f64, bool)> = all
                .iter()
                .map(|l| (l.operations_to_failure as f64, !l.censored))
                .collect();
            prop_assert_eq!(
                crate::life::analyse_lives(&first.lives()),
                crate::life::analyse(&pairs)
            );
        }
    }
}
