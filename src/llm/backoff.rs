//! Retry timing: exponential backoff with seeded jitter, and the server's `Retry-After`.
//!
//! The delay before retry `n` (1-based) is `min(max, base · 2^(n-1))` scaled by a jitter factor in
//! [0.5, 1) drawn from the request's seed and `n` (so a rerun waits the same), and never less than a
//! `Retry-After` the server sent. Whether that wait fits in the call's time limit is the client's
//! decision (a server asking for an hour ends the call at once rather than stalling a run).

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use crate::rng::{splitmix64, unit_f64};

/// The delay before retry `retry` (1-based).
pub(crate) fn delay(
    base: Duration,
    max: Duration,
    retry: u32,
    seed: u64,
    retry_after: Option<Duration>,
) -> Duration {
    let exp = base.saturating_mul(1u32 << (retry.saturating_sub(1)).min(20));
    let capped = exp.min(max);
    let u = unit_f64(splitmix64(
        seed ^ u64::from(retry).wrapping_mul(0x2545_f491_4f6c_dd1d),
    ));
    let jittered = capped.mul_f64(0.5 + 0.5 * u);
    match retry_after {
        Some(ra) => jittered.max(ra),
        None => jittered,
    }
}

/// Parses a `Retry-After` value: delay seconds (`"3"`, also `"1.5"` as some servers send) or an HTTP
/// date (`Wed, 21 Oct 2015 07:28:00 GMT`), relative to `now`. A date in the past is zero.
pub(crate) fn parse_retry_after(value: &str, now: SystemTime) -> Option<Duration> {
    let v = value.trim();
    if let Ok(s) = v.parse::<f64>() {
        return (s.is_finite() && s >= 0.0).then(|| Duration::from_secs_f64(s.min(1e7)));
    }
    let at = parse_http_date(v)?;
    let now = now.duration_since(UNIX_EPOCH).ok()?.as_secs();
    Some(Duration::from_secs(at.saturating_sub(now)))
}

/// IMF-fixdate (RFC 9110 §5.6.7) to Unix seconds.
fn parse_http_date(s: &str) -> Option<u64> {
    // "Wed, 21 Oct 2015 07:28:00 GMT"
    let rest = s.split_once(", ")?.1;
    let mut it = rest.split_whitespace();
    let day: u64 = it.next()?.parse().ok()?;
    let month = match it.next()? {
        "Jan" => 1,
        "Feb" => 2,
        "Mar" => 3,
        "Apr" => 4,
        "May" => 5,
        "Jun" => 6,
        "Jul" => 7,
        "Aug" => 8,
        "Sep" => 9,
        "Oct" => 10,
        "Nov" => 11,
        "Dec" => 12,
        _ => return None,
    };
    let year: i64 = it.next()?.parse().ok()?;
    let mut hms = it.next()?.split(':');
    let h: u64 = hms.next()?.parse().ok()?;
    let m: u64 = hms.next()?.parse().ok()?;
    let sec: u64 = hms.next()?.parse().ok()?;
    if it.next()? != "GMT" || !(1..=31).contains(&day) || h > 23 || m > 59 || sec > 60 {
        return None;
    }
    // Days from the civil date (Howard Hinnant's algorithm).
    let y = if month <= 2 { year - 1 } else { year };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (month + 9) % 12;
    let doy = (153 * mp + 2) / 5 + day as i64 - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    let days = era * 146_097 + doe - 719_468;
    u64::try_from(days)
        .ok()
        .map(|d| d * 86_400 + h * 3600 + m * 60 + sec)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn delays_double_jitter_within_half_to_one_and_repeat_for_a_seed() {
        let b = Duration::from_millis(100);
        let max = Duration::from_secs(10);
        for retry in 1..6 {
            let d = delay(b, max, retry, 42, None);
            let full = b * (1 << (retry - 1));
            assert!(d >= full / 2 && d < full, "retry {retry}: {d:?}");
            assert_eq!(d, delay(b, max, retry, 42, None));
        }
        assert_ne!(delay(b, max, 3, 1, None), delay(b, max, 3, 2, None));
        assert!(delay(b, max, 40, 1, None) <= max);
    }

    #[test]
    fn retry_after_is_a_floor_left_for_the_client_to_judge() {
        let b = Duration::from_millis(10);
        let max = Duration::from_secs(5);
        assert_eq!(
            delay(b, max, 1, 0, Some(Duration::from_secs(2))),
            Duration::from_secs(2)
        );
        // Not silently shortened: the client compares it with the call's time left.
        assert_eq!(
            delay(b, max, 1, 0, Some(Duration::from_secs(3600))),
            Duration::from_secs(3600)
        );
    }

    #[test]
    fn retry_after_values_parse_as_seconds_or_http_dates() {
        let now = UNIX_EPOCH + Duration::from_secs(1_445_412_470); // 2015-10-21 07:27:50 GMT
        assert_eq!(parse_retry_after("3", now), Some(Duration::from_secs(3)));
        assert_eq!(
            parse_retry_after(" 0.5 ", now),
            Some(Duration::from_millis(500))
        );
        assert_eq!(
            parse_retry_after("Wed, 21 Oct 2015 07:28:00 GMT", now),
            Some(Duration::from_secs(10))
        );
        assert_eq!(
            parse_retry_after("Wed, 21 Oct 2015 07:00:00 GMT", now),
            Some(Duration::ZERO)
        );
        assert_eq!(parse_retry_after("soon", now), None);
        assert_eq!(parse_retry_after("-1", now), None);
    }
}
