//! The data a pool simulation needs besides the balls: the table geometry, the ball parameters and the
//! cue specification, read from one table file (`data/tables/pooltool_7ft.json` by default).
//!
//! A table file holds `w`, `l`, `linear`, `circular`, `pockets` (pooltool's geometry, see
//! [`Table::from_json_str`]), `ball_params` ([`BallParams`]) and `cue_specs` ([`CueSpecs`]); other keys
//! are ignored. Another table is loaded with [`PoolConfig::from_file`].

use std::path::Path;
use std::sync::Arc;

use super::error::{PoolError, Result};
use super::params::{BallParams, CueSpecs, DEFAULT_TABLE_JSON};
use super::table::Table;

/// Table, ball parameters and cue specs: everything physical that is not a ball position.
#[derive(Debug, Clone)]
pub struct PoolConfig {
    /// A short name for the table (the file stem; `pooltool_7ft` for the default).
    pub name: String,
    /// The table geometry, shared by every simulation of the config.
    pub table: Arc<Table>,
    /// Parameters of every ball (pooltool `BallParams`, SI units).
    pub ball: BallParams,
    /// The cue (pooltool `CueSpecs`).
    pub cue: CueSpecs,
}

impl PoolConfig {
    /// pooltool 0.6.0's default 7-ft pocket table with `POOL_GENERIC` balls and the default cue.
    pub fn default_7ft() -> PoolConfig {
        PoolConfig::from_json_str("pooltool_7ft", DEFAULT_TABLE_JSON)
            .expect("the compiled-in table file is valid")
    }

    /// A config from the text of a table file.
    pub fn from_json_str(name: &str, json: &str) -> Result<PoolConfig> {
        Ok(PoolConfig {
            name: name.to_string(),
            table: Arc::new(Table::from_json_str(json)?),
            ball: BallParams::from_table_json(json)?,
            cue: CueSpecs::from_table_json(json)?,
        })
    }

    /// A config from a table file on disk; errors name the file.
    pub fn from_file(path: &Path) -> Result<PoolConfig> {
        let text = std::fs::read_to_string(path).map_err(|e| {
            PoolError::Data(format!("{}: cannot read table file: {e}", path.display()))
        })?;
        let name = path
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or("table")
            .to_string();
        PoolConfig::from_json_str(&name, &text)
            .map_err(|e| PoolError::Data(format!("{}: {e}", path.display())))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_table_loads_and_a_bad_file_names_itself() {
        let c = PoolConfig::default_7ft();
        assert_eq!(c.table.pockets.len(), 6);
        assert_eq!(c.ball.r, 0.028575);
        let err = PoolConfig::from_file(Path::new("/nonexistent/table.json")).unwrap_err();
        assert!(err.to_string().contains("/nonexistent/table.json"));
        assert!(PoolConfig::from_json_str("x", "{}").is_err());
    }
}
