//! [`ShortStr`]: an immutable string that keeps up to [`ShortStr::INLINE`] bytes inside itself, for
//! the short per-object strings of a trace (ball ids `"cue"`, `"1"` … `"15"`, the kind `"ball"`,
//! motion states such as `"stationary"`) that every ball of every timestep carries.
//!
//! **Owns:** the type and its conversions. **Does not:** intern or share strings; a longer string
//! (rare: only a hand-written trace gives one) is one heap allocation, like a `String`.
//!
//! Making, cloning and dropping a short one never allocates: building the paper-layout [`Trace`]
//! of a billiards shot (three strings per ball per timestep) used to spend a quarter of an
//! optimisation sample's CPU in `malloc` and `free` (docs/performance.md, "The per-sample trace").
//! It reads as a `&str` (`Deref`), compares equal to `str`, `&str` and `String`, orders and hashes
//! as its text, prints (`Display`, `Debug`) and serialises (serde) exactly as the `String` it
//! replaces, so every serialised form of a trace is unchanged.
//!
//! [`Trace`]: super::Trace

use std::borrow::Borrow;
use std::cmp::Ordering;
use std::fmt;
use std::hash::{Hash, Hasher};
use std::num::NonZeroU8;
use std::ops::Deref;

use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// An immutable UTF-8 string stored inline when it is at most [`ShortStr::INLINE`] bytes long.
#[derive(Clone)]
pub struct ShortStr(Repr);

/// A string is `Inline` exactly when it is at most [`ShortStr::INLINE`] bytes long (equality
/// relies on it).
#[derive(Clone)]
enum Repr {
    /// A string of at most [`ShortStr::INLINE`] bytes, the rest of the buffer zero.
    Inline(Inline),
    /// A longer string.
    Heap(Box<str>),
}

/// The bytes and their length plus one, last (`repr(C)`): a length byte that is never zero lets
/// the enum tell `Heap` (whose pointer and length fill the first 16 bytes) by a zero there, so a
/// `ShortStr` is as large as a `String`.
#[derive(Clone, Copy)]
#[repr(C)]
struct Inline {
    bytes: [u8; ShortStr::INLINE],
    len_plus_one: NonZeroU8,
}

impl ShortStr {
    /// The longest string kept inline, in bytes.
    pub const INLINE: usize = 23;

    /// The string `s`: inline when it fits, else one heap allocation.
    pub fn new(s: &str) -> ShortStr {
        let len = s.len();
        if len <= Self::INLINE {
            let mut bytes = [0u8; Self::INLINE];
            bytes[..len].copy_from_slice(s.as_bytes());
            // `len` ≤ 23, so the sum neither overflows nor saturates.
            let len_plus_one = NonZeroU8::MIN.saturating_add(len as u8);
            ShortStr(Repr::Inline(Inline {
                bytes,
                len_plus_one,
            }))
        } else {
            ShortStr(Repr::Heap(s.into()))
        }
    }

    /// The text.
    pub fn as_str(&self) -> &str {
        match &self.0 {
            Repr::Inline(Inline {
                bytes,
                len_plus_one,
            }) => {
                let bytes = &bytes[..usize::from(len_plus_one.get() - 1)];
                debug_assert!(std::str::from_utf8(bytes).is_ok());
                // SAFETY: `ShortStr::new` is the only writer of `Inline`, and it copies the whole
                // of a `&str` (valid UTF-8) into `bytes[..len]`; nothing mutates them afterwards.
                // (Checking here instead cost ~10 ns per call, and the detector protocol reads
                // three of these per ball per timestep.)
                unsafe { std::str::from_utf8_unchecked(bytes) }
            }
            Repr::Heap(s) => s,
        }
    }

    /// Whether the text is held inline (no heap allocation).
    pub fn is_inline(&self) -> bool {
        matches!(self.0, Repr::Inline(_))
    }
}

impl Default for ShortStr {
    /// The empty string.
    fn default() -> Self {
        ShortStr::new("")
    }
}

impl Deref for ShortStr {
    type Target = str;

    fn deref(&self) -> &str {
        self.as_str()
    }
}

impl AsRef<str> for ShortStr {
    fn as_ref(&self) -> &str {
        self.as_str()
    }
}

impl Borrow<str> for ShortStr {
    fn borrow(&self) -> &str {
        self.as_str()
    }
}

impl From<&str> for ShortStr {
    fn from(s: &str) -> Self {
        ShortStr::new(s)
    }
}

impl From<&String> for ShortStr {
    fn from(s: &String) -> Self {
        ShortStr::new(s)
    }
}

impl From<String> for ShortStr {
    /// Inline when it fits; a longer string keeps its buffer (no copy).
    fn from(s: String) -> Self {
        if s.len() <= Self::INLINE {
            ShortStr::new(&s)
        } else {
            ShortStr(Repr::Heap(s.into_boxed_str()))
        }
    }
}

impl From<ShortStr> for String {
    fn from(s: ShortStr) -> Self {
        match s.0 {
            Repr::Heap(b) => b.into_string(),
            Repr::Inline(_) => s.as_str().to_string(),
        }
    }
}

impl fmt::Display for ShortStr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(self.as_str(), f)
    }
}

impl fmt::Debug for ShortStr {
    /// As a `String` prints: quoted and escaped.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Debug::fmt(self.as_str(), f)
    }
}

impl PartialEq for ShortStr {
    /// Two inline strings compare as their fixed-size buffers (unused bytes are always zero); a
    /// heap string is longer than any inline one, so the two kinds never compare equal.
    fn eq(&self, other: &Self) -> bool {
        match (&self.0, &other.0) {
            (Repr::Inline(a), Repr::Inline(b)) => {
                a.len_plus_one == b.len_plus_one && a.bytes == b.bytes
            }
            (Repr::Heap(a), Repr::Heap(b)) => a == b,
            _ => false,
        }
    }
}

impl Eq for ShortStr {}

impl PartialOrd for ShortStr {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for ShortStr {
    fn cmp(&self, other: &Self) -> Ordering {
        self.as_str().cmp(other.as_str())
    }
}

impl Hash for ShortStr {
    /// As the text hashes (consistent with `Borrow<str>`).
    fn hash<H: Hasher>(&self, state: &mut H) {
        self.as_str().hash(state)
    }
}

impl PartialEq<str> for ShortStr {
    fn eq(&self, other: &str) -> bool {
        self.as_str() == other
    }
}

impl PartialEq<&str> for ShortStr {
    fn eq(&self, other: &&str) -> bool {
        self.as_str() == *other
    }
}

impl PartialEq<String> for ShortStr {
    fn eq(&self, other: &String) -> bool {
        self.as_str() == other.as_str()
    }
}

impl PartialEq<ShortStr> for str {
    fn eq(&self, other: &ShortStr) -> bool {
        self == other.as_str()
    }
}

impl PartialEq<ShortStr> for &str {
    fn eq(&self, other: &ShortStr) -> bool {
        *self == other.as_str()
    }
}

impl PartialEq<ShortStr> for String {
    fn eq(&self, other: &ShortStr) -> bool {
        self.as_str() == other.as_str()
    }
}

impl Serialize for ShortStr {
    /// As a plain string.
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(self.as_str())
    }
}

impl<'de> Deserialize<'de> for ShortStr {
    /// From a plain string.
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Visit;
        impl serde::de::Visitor<'_> for Visit {
            type Value = ShortStr;

            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a string")
            }

            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<ShortStr, E> {
                Ok(ShortStr::new(v))
            }

            fn visit_string<E: serde::de::Error>(self, v: String) -> Result<ShortStr, E> {
                Ok(ShortStr::from(v))
            }
        }
        deserializer.deserialize_str(Visit)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::hash_map::DefaultHasher;

    fn hash_of<T: Hash + ?Sized>(x: &T) -> u64 {
        let mut h = DefaultHasher::new();
        x.hash(&mut h);
        h.finish()
    }

    #[test]
    fn short_strings_stay_inline_and_long_ones_round_trip() {
        for s in [
            "",
            "cue",
            "15",
            "ball",
            "stationary",
            "é9ü",
            "exactly-23-bytes-long!!",
        ] {
            let x = ShortStr::from(s);
            assert!(x.is_inline(), "{s:?}");
            assert_eq!(x.as_str(), s);
            assert_eq!(x.len(), s.len());
        }
        let long = "a ball id far longer than twenty-three bytes";
        for x in [ShortStr::from(long), ShortStr::from(long.to_string())] {
            assert!(!x.is_inline());
            assert_eq!(x, long);
            assert_eq!(String::from(x.clone()), long);
        }
        // A multi-byte character straddling the inline limit goes to the heap whole.
        let edge = format!("{}é", "x".repeat(22));
        assert_eq!(edge.len(), 24);
        assert_eq!(ShortStr::from(edge.as_str()), edge);
        assert_eq!(
            std::mem::size_of::<ShortStr>(),
            std::mem::size_of::<String>()
        );
    }

    #[test]
    fn compares_hashes_and_prints_as_its_text() {
        let x = ShortStr::from("cue");
        let (text, owned, other) = ("cue", String::from("cue"), String::from("9"));
        assert!(x == text);
        assert!(text == x);
        assert!(x == *text);
        assert!(x == owned);
        assert!(owned == x);
        assert!(x != "9");
        assert!(other != x);
        // Equal texts compare equal however they were made; a prefix or a longer text does not.
        let long = "x".repeat(30);
        assert_eq!(ShortStr::from(long.clone()), ShortStr::from(long.as_str()));
        assert_ne!(ShortStr::from(long.as_str()), ShortStr::from(&long[..23]));
        assert_eq!(ShortStr::from("cue".to_string()), x);
        assert_ne!(ShortStr::from("cu"), x);
        assert_ne!(ShortStr::from("cue\0"), x);
        assert_ne!(ShortStr::from(""), ShortStr::from("\0"));
        let (one, fifteen) = (ShortStr::from("1"), ShortStr::from("15"));
        assert!(one < fifteen);
        assert_eq!(hash_of(&x), hash_of("cue"));
        assert_eq!(format!("{x} {x:?}"), "cue \"cue\"");
        assert_eq!(
            format!("{:?}", ShortStr::from("a\"b")),
            format!("{:?}", "a\"b")
        );
        assert_eq!(ShortStr::default(), "");
        assert!(x.eq_ignore_ascii_case("CUE"));
    }

    #[test]
    fn serialises_as_a_plain_string() {
        for s in ["rolling", "a ball id far longer than twenty-three bytes"] {
            let x = ShortStr::from(s);
            let json = serde_json::to_string(&x).unwrap();
            assert_eq!(json, serde_json::to_string(s).unwrap());
            let back: ShortStr = serde_json::from_str(&json).unwrap();
            assert_eq!(back, x);
            let owned: ShortStr = serde_json::from_value(serde_json::json!(s)).unwrap();
            assert_eq!(owned, x);
        }
        assert!(serde_json::from_str::<ShortStr>("3").is_err());
    }
}
