//! The split of scenes into train (SFT records), dpo (DPO pairs) and test (held-out SFT
//! records): deterministic, by hash of the scene id, stratified by table type; SFT and DPO
//! never share a scene because each scene is in exactly one split.
//!
//! Systematic stratified sampling: within each table type, scenes are ordered by the hash of
//! the seed and the scene id and given their quantile `(j + 0.5) / n_type`; all scenes are then
//! ordered by quantile (ties by table type, then hash) and the sequence is cut into the split
//! sizes. Each split so receives every table type in proportion, and the split sizes follow the
//! ratios over the whole dataset, even when a table type has only a few scenes. The sizes are
//! the ratios apportioned by largest remainder, and a split with a positive ratio gets at least
//! one scene when there are enough (so a small dataset still has DPO pairs). Adding scenes can
//! move others between splits: `records/split.json` records the assignment of each run.

use std::collections::BTreeMap;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::seeding::hash_hex;

/// The `[records.split]` section: the share of scenes in each split (they sum to 1).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct SplitRatios {
    /// Share of scenes whose tasks become SFT records (records/sft.json, trl_sft.jsonl).
    pub train: f64,
    /// Share of scenes whose tasks become DPO pairs (records/dpo.json, trl_dpo.jsonl).
    pub dpo: f64,
    /// Share of scenes held out for evaluation (records/test.json, trl_test.jsonl).
    pub test: f64,
}

impl Default for SplitRatios {
    fn default() -> Self {
        Self {
            train: 0.8,
            dpo: 0.1,
            test: 0.1,
        }
    }
}

impl SplitRatios {
    pub(crate) fn problems(&self) -> Vec<String> {
        let mut problems = Vec::new();
        for (name, value) in [
            ("train", self.train),
            ("dpo", self.dpo),
            ("test", self.test),
        ] {
            if !(0.0..=1.0).contains(&value) {
                problems.push(format!(
                    "[records.split] {name} is {value} (expected 0 to 1)"
                ));
            }
        }
        let sum = self.train + self.dpo + self.test;
        if (sum - 1.0).abs() > 1e-9 {
            problems.push(format!(
                "[records.split] train + dpo + test is {sum} (expected 1)"
            ));
        }
        problems
    }

    /// The ratios by split name.
    pub fn by_name(&self) -> BTreeMap<String, f64> {
        BTreeMap::from([
            ("train".to_owned(), self.train),
            ("dpo".to_owned(), self.dpo),
            ("test".to_owned(), self.test),
        ])
    }
}

/// A split.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Split {
    /// SFT records.
    Train,
    /// DPO pairs.
    Dpo,
    /// Held-out SFT records.
    Test,
}

impl Split {
    /// `train`, `dpo` or `test`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Train => "train",
            Self::Dpo => "dpo",
            Self::Test => "test",
        }
    }
}

/// The split of each scene, given as `(table_type, scene_id)`, in the input's order.
pub fn assign(scenes: &[(String, String)], ratios: &SplitRatios, seed: u64) -> Vec<Split> {
    let hashes: Vec<String> = scenes
        .iter()
        .map(|(_, scene_id)| hash_hex(seed, &["split", scene_id]))
        .collect();
    let mut by_type: BTreeMap<&str, Vec<usize>> = BTreeMap::new();
    for (i, (table_type, _)) in scenes.iter().enumerate() {
        by_type.entry(table_type).or_default().push(i);
    }
    let mut quantile = vec![0.0; scenes.len()];
    for members in by_type.values_mut() {
        members.sort_by(|a, b| hashes[*a].cmp(&hashes[*b]));
        let n = members.len() as f64;
        for (j, i) in members.iter().enumerate() {
            quantile[*i] = (j as f64 + 0.5) / n;
        }
    }
    let mut sequence: Vec<usize> = (0..scenes.len()).collect();
    sequence.sort_by(|a, b| {
        quantile[*a]
            .total_cmp(&quantile[*b])
            .then_with(|| scenes[*a].0.cmp(&scenes[*b].0))
            .then_with(|| hashes[*a].cmp(&hashes[*b]))
    });
    let [train, dpo, _] = sizes(scenes.len(), ratios);
    let (train_end, dpo_end) = (train, train + dpo);
    let mut splits = vec![Split::Test; scenes.len()];
    for (position, i) in sequence.into_iter().enumerate() {
        splits[i] = if position < train_end {
            Split::Train
        } else if position < dpo_end {
            Split::Dpo
        } else {
            Split::Test
        };
    }
    splits
}

/// The number of scenes of each split (train, dpo, test): `n · ratio` apportioned by largest
/// remainder (ties to the earlier split), then every split with a positive ratio given one
/// scene, taken from the largest, while it has more than one.
pub fn sizes(n: usize, ratios: &SplitRatios) -> [usize; 3] {
    let shares = [ratios.train, ratios.dpo, ratios.test];
    let exact: Vec<f64> = shares.iter().map(|r| n as f64 * r).collect();
    let mut sizes: [usize; 3] = [0; 3];
    for (size, value) in sizes.iter_mut().zip(&exact) {
        *size = value.floor() as usize;
    }
    let mut order: Vec<usize> = (0..3).collect();
    order.sort_by(|a, b| {
        let fa = exact[*a] - exact[*a].floor();
        let fb = exact[*b] - exact[*b].floor();
        fb.total_cmp(&fa).then(a.cmp(b))
    });
    let mut left = n.saturating_sub(sizes.iter().sum());
    for k in order.iter().cycle().take(3 * n.max(1)) {
        if left == 0 {
            break;
        }
        if shares[*k] > 0.0 {
            sizes[*k] += 1;
            left -= 1;
        }
    }
    for k in 0..3 {
        if shares[k] > 0.0 && sizes[k] == 0 {
            let largest = (0..3)
                .max_by_key(|j| (sizes[*j], std::cmp::Reverse(*j)))
                .unwrap_or(0);
            if sizes[largest] > 1 {
                sizes[largest] -= 1;
                sizes[k] += 1;
            }
        }
    }
    sizes
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn scenes(counts: &[(&str, usize)]) -> Vec<(String, String)> {
        counts
            .iter()
            .flat_map(|(t, n)| (0..*n).map(move |i| ((*t).to_owned(), format!("{t}_{i:04}"))))
            .collect()
    }

    #[test]
    fn sizes_follow_the_ratios_and_every_type_is_spread() {
        let list = scenes(&[
            ("office_table", 500),
            ("coffee_table", 300),
            ("bathroom_vanity", 200),
        ]);
        let splits = assign(&list, &SplitRatios::default(), 0);
        let count = |t: &str, s: Split| {
            list.iter()
                .zip(&splits)
                .filter(|((tt, _), ss)| tt == t && **ss == s)
                .count()
        };
        assert_eq!(splits.iter().filter(|s| **s == Split::Train).count(), 800);
        assert_eq!(splits.iter().filter(|s| **s == Split::Dpo).count(), 100);
        for (t, n) in [
            ("office_table", 500),
            ("coffee_table", 300),
            ("bathroom_vanity", 200),
        ] {
            let train = count(t, Split::Train) as f64;
            assert!((train - 0.8 * n as f64).abs() <= 1.0, "{t}: {train}");
            let dpo = count(t, Split::Dpo) as f64;
            assert!((dpo - 0.1 * n as f64).abs() <= 1.0, "{t}: {dpo}");
        }
    }

    #[test]
    fn small_datasets_still_get_a_dpo_scene() {
        let list = scenes(&[
            ("office_table", 4),
            ("kitchen_counter", 4),
            ("coffee_table", 4),
        ]);
        let splits = assign(&list, &SplitRatios::default(), 7);
        assert_eq!(splits.iter().filter(|s| **s == Split::Train).count(), 10);
        assert_eq!(splits.iter().filter(|s| **s == Split::Dpo).count(), 1);
        assert_eq!(splits.iter().filter(|s| **s == Split::Test).count(), 1);
    }

    #[test]
    fn sizes_apportion_by_largest_remainder_with_one_scene_per_split() {
        let default = SplitRatios::default();
        assert_eq!(sizes(1000, &default), [800, 100, 100]);
        assert_eq!(sizes(7, &default), [5, 1, 1]);
        assert_eq!(sizes(3, &default), [1, 1, 1]);
        assert_eq!(sizes(2, &default), [1, 1, 0]);
        assert_eq!(sizes(1, &default), [1, 0, 0]);
        assert_eq!(sizes(0, &default), [0, 0, 0]);
        let no_test = SplitRatios {
            train: 0.9,
            dpo: 0.1,
            test: 0.0,
        };
        assert_eq!(sizes(5, &no_test), [4, 1, 0]);
    }

    proptest! {
        #[test]
        fn sizes_add_up(n in 0usize..5000, a in 0.0f64..1.0, b in 0.0f64..1.0) {
            let (train, dpo) = (a, (1.0 - a) * b);
            let ratios = SplitRatios { train, dpo, test: 1.0 - train - dpo };
            let got = sizes(n, &ratios);
            prop_assert_eq!(got.iter().sum::<usize>(), n);
            for (size, ratio) in got.iter().zip([train, dpo, 1.0 - train - dpo]) {
                prop_assert!((*size as f64 - n as f64 * ratio).abs() <= 2.0);
            }
        }

        #[test]
        fn the_assignment_is_a_function_of_the_scene_set(
            n in 1usize..60, seed in 0u64..1000, rotate in 0usize..60
        ) {
            let list = scenes(&[("a", n), ("b", n / 2 + 1)]);
            let splits = assign(&list, &SplitRatios::default(), seed);
            // Order of the input does not matter.
            let mut rotated = list.clone();
            rotated.rotate_left(rotate % list.len());
            let again = assign(&rotated, &SplitRatios::default(), seed);
            for (scene, split) in rotated.iter().zip(&again) {
                let i = list.iter().position(|s| s == scene).expect("same scenes");
                prop_assert_eq!(splits[i], *split);
            }
        }
    }
}
