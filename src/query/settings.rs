//! How much a query may use and where it runs: the memory pool, the time limit, the number of
//! partitions and the engine.
//!
//! **Owns:** [`QuerySettings`] and its defaults, the size syntax of memory limits ([`MemoryLimit`]:
//! `4GiB`, `512M`, `25%` of the machine's memory), reading the `ANNOTRACE_SQL_MEMORY_LIMIT`,
//! `ANNOTRACE_SQL_TIMEOUT` and `ANNOTRACE_SQL_ENGINE` variables through a lookup the caller passes
//! ([`QuerySettings::from_lookup`]),
//! and the machine's memory ([`machine_memory`]). **Does not:** build the DataFusion session (that is
//! [`RunQuery`](super::RunQuery)) nor enforce anything itself.
//!
//! Defaults (docs/reliability.md, "SQL"): memory pool [`DEFAULT_MEMORY_CAP`] (4 GiB) or half the
//! machine's memory, whichever is smaller; no time limit; one partition, so that float aggregates and
//! row order do not depend on thread timing and the same run gives byte-identical tables and exports.

use std::fmt;
use std::str::FromStr;
use std::time::Duration;

use super::engine::{ENV_ENGINE, Engine};

/// Environment variable for the memory limit of every query (CLI and pipeline stages).
pub const ENV_MEMORY_LIMIT: &str = "ANNOTRACE_SQL_MEMORY_LIMIT";
/// Environment variable for the time limit of every query, in seconds (CLI and pipeline stages).
pub const ENV_TIMEOUT: &str = "ANNOTRACE_SQL_TIMEOUT";
/// The default memory pool is at most this many bytes (4 GiB).
pub const DEFAULT_MEMORY_CAP: u64 = 4 << 30;
/// Spill files may take at most this multiple of the memory limit in the system's temporary folder.
pub const SPILL_FACTOR: u64 = 4;

/// A memory limit: a byte count, or a share of the machine's memory.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MemoryLimit {
    /// This many bytes.
    Bytes(u64),
    /// This percentage (0 < p ≤ 100) of [`machine_memory`].
    Percent(f64),
}

impl MemoryLimit {
    /// The limit in bytes (a percentage of the machine's memory, rounded down; at least 1 MiB).
    pub fn bytes(self) -> u64 {
        match self {
            MemoryLimit::Bytes(b) => b,
            MemoryLimit::Percent(p) => ((machine_memory() as f64 * p / 100.0) as u64).max(1 << 20),
        }
    }
}

impl Default for MemoryLimit {
    /// [`DEFAULT_MEMORY_CAP`] or half the machine's memory, whichever is smaller.
    fn default() -> Self {
        MemoryLimit::Bytes(DEFAULT_MEMORY_CAP.min(machine_memory() / 2).max(1 << 20))
    }
}

/// A memory limit that does not parse.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "{0:?} is not a memory size: use a byte count with an optional unit (K, M, G, T, KiB, MiB, GiB, TiB; \
     e.g. 512MiB, 4G) or a percentage of the machine's memory (e.g. 25%)"
)]
pub struct BadMemoryLimit(pub String);

impl FromStr for MemoryLimit {
    type Err = BadMemoryLimit;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || BadMemoryLimit(s.to_string());
        let t = s.trim();
        if let Some(p) = t.strip_suffix('%') {
            let p: f64 = p.trim().parse().map_err(|_| bad())?;
            return if p > 0.0 && p <= 100.0 {
                Ok(MemoryLimit::Percent(p))
            } else {
                Err(bad())
            };
        }
        let split = t
            .find(|c: char| !(c.is_ascii_digit() || c == '.'))
            .unwrap_or(t.len());
        let (number, unit) = t.split_at(split);
        let number: f64 = number.parse().map_err(|_| bad())?;
        let scale: u64 = match unit.trim().to_ascii_lowercase().as_str() {
            "" | "b" => 1,
            "k" | "kib" => 1 << 10,
            "m" | "mib" => 1 << 20,
            "g" | "gib" => 1 << 30,
            "t" | "tib" => 1 << 40,
            _ => return Err(bad()),
        };
        let bytes = number * scale as f64;
        if !(bytes.is_finite() && bytes >= 1.0 && bytes < u64::MAX as f64) {
            return Err(bad());
        }
        Ok(MemoryLimit::Bytes(bytes as u64))
    }
}

impl fmt::Display for MemoryLimit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MemoryLimit::Bytes(b) => f.write_str(&human_bytes(*b)),
            MemoryLimit::Percent(p) => write!(f, "{p}% of memory ({})", human_bytes(self.bytes())),
        }
    }
}

/// `4 GiB`, `512 MiB`, `1.5 GiB`, `900 B`.
pub fn human_bytes(b: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut v = b as f64;
    let mut unit = 0;
    while v >= 1024.0 && unit + 1 < UNITS.len() {
        v /= 1024.0;
        unit += 1;
    }
    if unit == 0 || v.fract() == 0.0 {
        format!("{v} {}", UNITS[unit])
    } else {
        format!("{v:.1} {}", UNITS[unit])
    }
}

/// The machine's memory in bytes: physical memory, or the cgroup (v2) limit if that is smaller.
pub fn machine_memory() -> u64 {
    // SAFETY: sysconf has no preconditions; it returns -1 for an unknown name.
    let (pages, page) = unsafe {
        (
            libc::sysconf(libc::_SC_PHYS_PAGES),
            libc::sysconf(libc::_SC_PAGESIZE),
        )
    };
    let physical = if pages > 0 && page > 0 {
        pages as u64 * page as u64
    } else {
        8 << 30
    };
    let cgroup = std::fs::read_to_string("/sys/fs/cgroup/memory.max")
        .ok()
        .and_then(|s| s.trim().parse::<u64>().ok());
    cgroup.map_or(physical, |c| c.min(physical))
}

/// A setting that does not parse (from a variable or a stage parameter).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{name}: {message}")]
pub struct BadSetting {
    /// The variable or parameter.
    pub name: String,
    /// What is wrong with it.
    pub message: String,
}

/// Parses a time limit in seconds (`30`, `2.5`); see [`timeout_from_secs`].
pub fn parse_timeout(s: &str) -> Result<Duration, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a number of seconds"))?;
    timeout_from_secs(v)
}

/// A time limit of `secs` seconds: positive, finite and at most 10⁹ s.
pub fn timeout_from_secs(secs: f64) -> Result<Duration, String> {
    if secs.is_finite() && secs > 0.0 && secs <= 1e9 {
        Ok(Duration::from_secs_f64(secs))
    } else {
        Err(format!(
            "{secs} must be a positive number of seconds (at most 1e9)"
        ))
    }
}

/// The limits and execution settings of one [`RunQuery`](super::RunQuery) session.
#[derive(Clone, Debug, PartialEq)]
pub struct QuerySettings {
    /// The session's memory pool. Operators that can spill (sorts, some aggregations) spill to the
    /// system's temporary folder (at most [`SPILL_FACTOR`] × the limit); others fail with
    /// [`QueryError::MemoryLimit`](super::QueryError::MemoryLimit).
    pub memory_limit: MemoryLimit,
    /// Time limit for each statement, from planning to the last row.
    pub timeout: Option<Duration>,
    /// DataFusion's `target_partitions`: 1 (the default) runs each query on one partition, which makes
    /// float aggregates (`avg`, `stddev`, `sum` of floats) and the row order of queries without
    /// `ORDER BY` reproducible. More partitions are faster on large runs but not reproducible.
    pub partitions: usize,
    /// Where the query runs: this process (the default) or a Ballista cluster (`query::engine`). On a
    /// cluster the memory limit is the executors' own; the time limit still applies here.
    pub engine: Engine,
}

impl Default for QuerySettings {
    fn default() -> Self {
        QuerySettings {
            memory_limit: MemoryLimit::default(),
            timeout: None,
            partitions: 1,
            engine: Engine::Local,
        }
    }
}

impl QuerySettings {
    /// The defaults, overridden by [`ENV_MEMORY_LIMIT`], [`ENV_TIMEOUT`] and [`ENV_ENGINE`] as `lookup` returns them
    /// (`|k| std::env::var(k).ok()` in the program; a map in tests). Empty values count as unset.
    pub fn from_lookup(lookup: &dyn Fn(&str) -> Option<String>) -> Result<Self, BadSetting> {
        let mut s = QuerySettings::default();
        if let Some(v) = lookup(ENV_MEMORY_LIMIT).filter(|v| !v.trim().is_empty()) {
            s.memory_limit = v.parse().map_err(|e: BadMemoryLimit| BadSetting {
                name: ENV_MEMORY_LIMIT.into(),
                message: e.to_string(),
            })?;
        }
        if let Some(v) = lookup(ENV_TIMEOUT).filter(|v| !v.trim().is_empty()) {
            s.timeout = Some(parse_timeout(&v).map_err(|message| BadSetting {
                name: ENV_TIMEOUT.into(),
                message,
            })?);
        }
        if let Some(v) = lookup(ENV_ENGINE).filter(|v| !v.trim().is_empty()) {
            s.engine = v.parse().map_err(|e: super::BadEngine| BadSetting {
                name: ENV_ENGINE.into(),
                message: e.to_string(),
            })?;
        }
        Ok(s)
    }

    /// [`from_lookup`](Self::from_lookup), then the limits given explicitly (a flag, a stage
    /// parameter) win over the variables.
    pub fn resolve(
        memory_limit: Option<MemoryLimit>,
        timeout: Option<Duration>,
        lookup: &dyn Fn(&str) -> Option<String>,
    ) -> Result<Self, BadSetting> {
        let mut s = Self::from_lookup(lookup)?;
        if let Some(m) = memory_limit {
            s.memory_limit = m;
        }
        if timeout.is_some() {
            s.timeout = timeout;
        }
        Ok(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_with_binary_units_and_percentages() {
        assert_eq!("1024".parse(), Ok(MemoryLimit::Bytes(1024)));
        assert_eq!("512MiB".parse(), Ok(MemoryLimit::Bytes(512 << 20)));
        assert_eq!("4G".parse(), Ok(MemoryLimit::Bytes(4 << 30)));
        assert_eq!(" 1.5 gib ".parse(), Ok(MemoryLimit::Bytes(3 << 29)));
        assert_eq!("2k".parse(), Ok(MemoryLimit::Bytes(2048)));
        assert_eq!("25%".parse(), Ok(MemoryLimit::Percent(25.0)));
        for bad in [
            "", "0", "-1G", "1X", "G", "0%", "150%", "1e400", "nan", "1.2.3M",
        ] {
            assert!(bad.parse::<MemoryLimit>().is_err(), "{bad:?} parsed");
        }
    }

    #[test]
    fn defaults_are_bounded_and_single_partition() {
        let s = QuerySettings::default();
        let b = s.memory_limit.bytes();
        assert!((1 << 20..=DEFAULT_MEMORY_CAP).contains(&b));
        assert!(b <= machine_memory());
        assert_eq!(s.partitions, 1);
        assert_eq!(s.timeout, None);
        assert!(MemoryLimit::Percent(50.0).bytes() <= machine_memory());
    }

    #[test]
    fn variables_override_defaults_and_bad_values_name_the_variable() {
        let env = |pairs: &'static [(&'static str, &'static str)]| {
            move |k: &str| {
                pairs
                    .iter()
                    .find(|(n, _)| *n == k)
                    .map(|(_, v)| v.to_string())
            }
        };
        let s =
            QuerySettings::from_lookup(&env(&[(ENV_MEMORY_LIMIT, "64M"), (ENV_TIMEOUT, "2.5")]))
                .unwrap();
        assert_eq!(s.memory_limit, MemoryLimit::Bytes(64 << 20));
        assert_eq!(s.timeout, Some(Duration::from_millis(2500)));
        let s = QuerySettings::from_lookup(&env(&[(ENV_MEMORY_LIMIT, " ")])).unwrap();
        assert_eq!(s, QuerySettings::default());
        let e = QuerySettings::from_lookup(&env(&[(ENV_MEMORY_LIMIT, "lots")])).unwrap_err();
        assert_eq!(e.name, ENV_MEMORY_LIMIT);
        let e = QuerySettings::from_lookup(&env(&[(ENV_TIMEOUT, "-3")])).unwrap_err();
        assert_eq!(e.name, ENV_TIMEOUT);
        let s =
            QuerySettings::from_lookup(&env(&[(ENV_ENGINE, "ballista://sched:50051")])).unwrap();
        assert_eq!(s.engine.to_string(), "ballista://sched:50051");
        let e = QuerySettings::from_lookup(&env(&[(ENV_ENGINE, "spark://x")])).unwrap_err();
        assert_eq!(e.name, ENV_ENGINE);
        // Explicit limits win over the variables.
        let s = QuerySettings::resolve(
            Some(MemoryLimit::Bytes(1 << 20)),
            Some(Duration::from_secs(1)),
            &env(&[(ENV_MEMORY_LIMIT, "64M"), (ENV_TIMEOUT, "2.5")]),
        )
        .unwrap();
        assert_eq!(s.memory_limit, MemoryLimit::Bytes(1 << 20));
        assert_eq!(s.timeout, Some(Duration::from_secs(1)));
    }

    #[test]
    fn sizes_print_for_people() {
        assert_eq!(human_bytes(4 << 30), "4 GiB");
        assert_eq!(human_bytes(3 << 29), "1.5 GiB");
        assert_eq!(human_bytes(900), "900 B");
        assert_eq!(MemoryLimit::Bytes(64 << 20).to_string(), "64 MiB");
    }
}
