//! The names of the configuration's choices: [`FromStr`] reads them, [`Display`] writes them
//! (the same spellings as the serialised forms).
//!
//! [`Display`]: fmt::Display

use super::{GhostPolicy, PartitionKind, RollbackMode};
use std::fmt;
use std::str::FromStr;

impl RollbackMode {
    /// Every mode, in the order of the SPEC: cell, world, conservative.
    pub const ALL: [RollbackMode; 3] = [Self::Cell, Self::World, Self::Conservative];

    /// Its name: `cell`, `world` or `conservative`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Cell => "cell",
            Self::World => "world",
            Self::Conservative => "conservative",
        }
    }
}

impl fmt::Display for RollbackMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A rollback mode name that is none of `cell`, `world`, `conservative`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("`{0}` is not a rollback mode: use cell, world or conservative")]
pub struct UnknownMode(pub String);

impl FromStr for RollbackMode {
    type Err = UnknownMode;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| UnknownMode(s.to_string()))
    }
}

impl PartitionKind {
    /// Whether `KernelConfig::partition_seed` changes its territories (k-means and random;
    /// both kinds of blocks and an explicit map have nothing random).
    pub fn is_seeded(&self) -> bool {
        matches!(self, Self::KMeans | Self::Random)
    }

    /// Its name: `blocks`, `equal-blocks`, `kmeans`, `random`, or `explicit` for an
    /// explicit owner list (which [`FromStr`] does not read).
    pub fn name(&self) -> &'static str {
        match self {
            Self::Blocks => "blocks",
            Self::EqualBlocks => "equal-blocks",
            Self::KMeans => "kmeans",
            Self::Random => "random",
            Self::Explicit(_) => "explicit",
        }
    }
}

impl fmt::Display for PartitionKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A partitioner name that is none of `blocks`, `equal-blocks`, `kmeans`, `random`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("`{0}` is not a partitioner: use blocks, equal-blocks, kmeans or random")]
pub struct UnknownPartition(pub String);

impl FromStr for PartitionKind {
    type Err = UnknownPartition;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "blocks" => Ok(Self::Blocks),
            "equal-blocks" => Ok(Self::EqualBlocks),
            "kmeans" => Ok(Self::KMeans),
            "random" => Ok(Self::Random),
            other => Err(UnknownPartition(other.to_string())),
        }
    }
}

impl GhostPolicy {
    /// Its name: `delta` or `full`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Delta => "delta",
            Self::Full => "full",
        }
    }
}

impl fmt::Display for GhostPolicy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A ghost policy name that is neither `delta` nor `full`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("`{0}` is not a ghost policy: use delta or full")]
pub struct UnknownGhostPolicy(pub String);

impl FromStr for GhostPolicy {
    type Err = UnknownGhostPolicy;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "delta" => Ok(Self::Delta),
            "full" => Ok(Self::Full),
            other => Err(UnknownGhostPolicy(other.to_string())),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_read_back() {
        for m in RollbackMode::ALL {
            assert_eq!(m.to_string().parse::<RollbackMode>(), Ok(m));
        }
        for p in [
            PartitionKind::Blocks,
            PartitionKind::EqualBlocks,
            PartitionKind::KMeans,
            PartitionKind::Random,
        ] {
            assert_eq!(p.to_string().parse::<PartitionKind>(), Ok(p));
        }
        for g in [GhostPolicy::Delta, GhostPolicy::Full] {
            assert_eq!(g.to_string().parse::<GhostPolicy>(), Ok(g));
        }
        assert!("explicit".parse::<PartitionKind>().is_err());
        assert_eq!(
            "lazy".parse::<RollbackMode>().unwrap_err().to_string(),
            "`lazy` is not a rollback mode: use cell, world or conservative"
        );
    }
}
