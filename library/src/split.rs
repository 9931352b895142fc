//! Training, validation and test materials: a material's split is a pure function of the
//! library's seed and its cluster's key (the identifier of the cluster's first member,
//! [`crate::filter::clusters`]), so near-duplicates never straddle two splits, a material keeps
//! its split when others are added or removed, and the same sources give the same splits
//! (docs/data.md, "Splits").

use photomat_core::rng::{mix64, unit_f64};
use serde::{Deserialize, Serialize};

/// One of the three splits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Split {
    /// What the learned parts train on.
    Train,
    /// What picks snapshots and tunes settings.
    Validation,
    /// Held out: measured once, and rendered by an independent renderer
    /// (`validation/`).
    Test,
}

impl Split {
    /// Every split, in order.
    pub const ALL: [Split; 3] = [Split::Train, Split::Validation, Split::Test];

    /// The split's name (`train`, `validation`, `test`).
    pub fn name(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Validation => "validation",
            Split::Test => "test",
        }
    }
}

impl std::str::FromStr for Split {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        Split::ALL
            .into_iter()
            .find(|s| s.name() == text)
            .ok_or_else(|| format!("'{text}' is not a split: give train, validation or test"))
    }
}

/// The shares of the validation and test splits (the rest trains).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SplitShares {
    pub validation: f64,
    pub test: f64,
}

impl Default for SplitShares {
    /// 10 % each: with ~700 clusters, ~70 materials per held-out split.
    fn default() -> Self {
        Self {
            validation: 0.1,
            test: 0.1,
        }
    }
}

/// The split of the cluster whose key is `key`, for the library seed `seed`.
pub fn split_of(key: &str, seed: u64, shares: SplitShares) -> Split {
    // FNV-1a of the key, mixed with the seed: stable across platforms and Rust versions.
    let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
    for byte in key.bytes() {
        hash = (hash ^ byte as u64).wrapping_mul(0x0000_0100_0000_01b3);
    }
    let u = unit_f64(mix64(hash ^ mix64(seed)));
    if u < shares.test {
        Split::Test
    } else if u < shares.test + shares.validation {
        Split::Validation
    } else {
        Split::Train
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splits_are_stable_seeded_and_near_their_shares() {
        let shares = SplitShares::default();
        let keys: Vec<String> = (0..2000).map(|i| format!("pkg/material-{i}")).collect();
        let first: Vec<Split> = keys.iter().map(|k| split_of(k, 7, shares)).collect();
        // The same key always lands in the same split, whatever else is in the library.
        let again: Vec<Split> = keys.iter().rev().map(|k| split_of(k, 7, shares)).collect();
        assert!(first.iter().eq(again.iter().rev()));
        let test = first.iter().filter(|s| **s == Split::Test).count();
        let validation = first.iter().filter(|s| **s == Split::Validation).count();
        // 200 expected each; 4 standard deviations (√(2000·0.1·0.9) ≈ 13.4) either side.
        assert!((146..=254).contains(&test), "{test}");
        assert!((146..=254).contains(&validation), "{validation}");
        let other_seed: Vec<Split> = keys.iter().map(|k| split_of(k, 8, shares)).collect();
        assert_ne!(first, other_seed);
        assert_eq!("validation".parse::<Split>(), Ok(Split::Validation));
    }
}
