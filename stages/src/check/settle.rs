//! Settling (placeholder while the check is measured).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// The `[check.settling]` section of `mesa.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct SettleConfig {
    /// Rounds of push-apart and drop before a scene is given up.
    pub max_rounds: u32,
}

impl Default for SettleConfig {
    fn default() -> Self {
        Self { max_rounds: 40 }
    }
}

impl SettleConfig {
    /// What is wrong with the values.
    pub fn problems(&self) -> Vec<String> {
        Vec::new()
    }
}
