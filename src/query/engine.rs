//! Where a run's SQL executes: in this process (DataFusion), or on an Apache DataFusion Ballista cluster.
//!
//! **Owns:** [`Engine`] and its spelling (`local`, `ballista://HOST:PORT`, `ballista:standalone`), parsed
//! the same way from `query --engine`, the `engine` parameter of `sql` stages and the
//! `ANNOTRACE_SQL_ENGINE` variable; and [`Engine::check_built`], which says when this build cannot reach
//! an engine (the `ballista` cargo feature is off). **Does not:** connect to anything or register tables
//! (`query::ballista`, built with the feature).
//!
//! The spelling is parsed in every build, so a default build given `ballista://…` says which feature
//! to build with instead of calling it a bad value.

use std::fmt;
use std::str::FromStr;

/// Environment variable naming the engine of every query that reads the run's settings (`annotrace query`,
/// `sql` and `export` stages) when no flag or parameter names one.
pub const ENV_ENGINE: &str = "ANNOTRACE_SQL_ENGINE";
/// The port a Ballista scheduler listens on when the address names none.
pub const DEFAULT_BALLISTA_PORT: u16 = 50050;

/// The engine a query runs on.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub enum Engine {
    /// DataFusion in this process (the default).
    #[default]
    Local,
    /// A Ballista scheduler at `host:port` (`ballista://HOST[:PORT]`). Its executors read the run's
    /// files at the paths this process sees them, so the run folder must be on a file system they share.
    Ballista {
        /// Host name or address (IPv6 in brackets).
        host: String,
        /// Scheduler port.
        port: u16,
    },
    /// A Ballista scheduler and executor started inside this process for the query's session
    /// (`ballista:standalone`): the distributed planner and shuffle on one machine.
    BallistaStandalone,
}

impl Engine {
    /// Whether queries run in this process without Ballista.
    pub fn is_local(&self) -> bool {
        matches!(self, Engine::Local)
    }

    /// `Ok` when this build can run queries on the engine; otherwise the reason (Ballista engines need
    /// the `ballista` cargo feature).
    pub fn check_built(&self) -> Result<(), BadEngine> {
        if self.is_local() || cfg!(feature = "ballista") {
            Ok(())
        } else {
            Err(BadEngine(format!(
                "{self}: this annotrace was built without Ballista support; rebuild it with \
                 `cargo build --features ballista` (docs/pipelines.md, \"SQL on a Ballista cluster\")"
            )))
        }
    }
}

impl fmt::Display for Engine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Engine::Local => f.write_str("local"),
            Engine::Ballista { host, port } => write!(f, "ballista://{host}:{port}"),
            Engine::BallistaStandalone => f.write_str("ballista:standalone"),
        }
    }
}

/// An engine that does not parse, or that this build cannot use.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct BadEngine(pub String);

impl FromStr for Engine {
    type Err = BadEngine;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let t = s.trim();
        let bad = |why: &str| {
            BadEngine(format!(
                "{s:?} is not an SQL engine: {why} (use `local`, `ballista://HOST:PORT` or \
                 `ballista:standalone`)"
            ))
        };
        if t == "local" {
            return Ok(Engine::Local);
        }
        if t == "ballista:standalone" {
            return Ok(Engine::BallistaStandalone);
        }
        let Some(address) = t.strip_prefix("ballista://") else {
            return Err(bad("unknown engine"));
        };
        let address = address.strip_suffix('/').unwrap_or(address);
        // `[v6]:port`, `[v6]`, `host:port` or `host`.
        let (host, port) = if let Some(rest) = address.strip_prefix('[') {
            let (v6, after) = rest
                .split_once(']')
                .ok_or_else(|| bad("an IPv6 address needs its closing `]`"))?;
            if v6.is_empty() || !v6.chars().all(|c| c.is_ascii_hexdigit() || c == ':') {
                return Err(bad("not an IPv6 address in brackets"));
            }
            let port = match after {
                "" => None,
                p => Some(
                    p.strip_prefix(':')
                        .ok_or_else(|| bad("expected `:PORT` after the address"))?,
                ),
            };
            (format!("[{v6}]"), port)
        } else {
            match address.split_once(':') {
                Some((h, p)) => (h.to_string(), Some(p)),
                None => (address.to_string(), None),
            }
        };
        if host.is_empty() {
            return Err(bad("no host"));
        }
        if !host.starts_with('[')
            && !host
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '.' || c == '-' || c == '_')
        {
            return Err(bad(
                "a host name has letters, digits, `.`, `-` and `_` only",
            ));
        }
        let port = match port {
            None => DEFAULT_BALLISTA_PORT,
            Some(p) => match p.parse::<u16>() {
                Ok(p) if p > 0 => p,
                _ => return Err(bad("the port must be a number from 1 to 65535")),
            },
        };
        Ok(Engine::Ballista { host, port })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn engines_parse_and_print_back() {
        assert_eq!("local".parse(), Ok(Engine::Local));
        assert_eq!(
            " ballista:standalone ".parse(),
            Ok(Engine::BallistaStandalone)
        );
        for (text, host, port) in [
            ("ballista://sched.cluster:50051", "sched.cluster", 50051),
            ("ballista://10.0.0.7", "10.0.0.7", DEFAULT_BALLISTA_PORT),
            ("ballista://node-1/", "node-1", DEFAULT_BALLISTA_PORT),
            ("ballista://[::1]:7000", "[::1]", 7000),
            ("ballista://[fe80::2]", "[fe80::2]", DEFAULT_BALLISTA_PORT),
        ] {
            let e: Engine = text.parse().unwrap();
            assert_eq!(
                e,
                Engine::Ballista {
                    host: host.into(),
                    port
                },
                "{text}"
            );
            assert_eq!(e.to_string().parse::<Engine>().unwrap(), e);
        }
        assert_eq!(Engine::default().to_string(), "local");
    }

    #[test]
    fn bad_engines_say_what_is_wrong() {
        for (text, why) in [
            ("", "unknown engine"),
            ("duckdb", "unknown engine"),
            ("df://host:50050", "unknown engine"),
            ("ballista://", "no host"),
            ("ballista://:50050", "no host"),
            ("ballista://host:0", "port"),
            ("ballista://host:70000", "port"),
            ("ballista://host:http", "port"),
            ("ballista://host/path", "host name"),
            ("ballista://[::1", "closing"),
            ("ballista://[::1]x", "`:PORT`"),
            ("ballista://[zz]:1", "IPv6"),
        ] {
            let e = text.parse::<Engine>().unwrap_err().0;
            assert!(e.contains(why), "{text:?}: {e}");
            assert!(e.contains("ballista://HOST:PORT"), "{e}");
        }
    }

    #[test]
    fn only_ballista_builds_reach_ballista() {
        assert!(Engine::Local.check_built().is_ok());
        let remote: Engine = "ballista://h:1".parse().unwrap();
        for e in [remote, Engine::BallistaStandalone] {
            let built = e.check_built();
            assert_eq!(built.is_ok(), cfg!(feature = "ballista"), "{e}");
            if let Err(why) = built {
                assert!(why.0.contains("--features ballista"), "{why}");
            }
        }
    }
}
