//! Content hashes as text and as seeds: lower-case hex, SHA-256 in hex, and SHA-256 folded to a `u64`.
//!
//! Owns: the one hex encoder of the crate ([`hex`]) and the SHA-256 helpers every id, fingerprint
//! and string-keyed seed is built from ([`sha256_hex`], [`sha256_u64`], [`words_u64`]). Ids and
//! fingerprints written into tables and manifests are made of these, so their output is part of the
//! output format: changing one changes ids, fingerprints and every split seeded by a hash.
//!
//! Does not own: what goes into a hash (each caller decides its fields and separators), nor the
//! fast non-cryptographic generator ([`crate::rng`]).

use sha2::{Digest, Sha256};

/// Lower-case hex of bytes, two digits a byte.
pub fn hex(bytes: &[u8]) -> String {
    use std::fmt::Write;
    let mut s = String::with_capacity(bytes.len() * 2);
    for b in bytes {
        write!(s, "{b:02x}").expect("writing to a String");
    }
    s
}

/// The SHA-256 of `bytes` in lower-case hex (64 digits).
pub fn sha256_hex(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

/// The first 8 bytes, little-endian, of the SHA-256 of `parts` concatenated (no separators): a seed
/// or sort key from strings and numbers.
pub fn sha256_u64(parts: &[&[u8]]) -> u64 {
    let mut h = Sha256::new();
    for p in parts {
        h.update(p);
    }
    u64::from_le_bytes(h.finalize()[..8].try_into().expect("8 bytes"))
}

/// [`sha256_u64`] of the little-endian bytes of `words`: a seed mixed from several numbers.
pub fn words_u64(words: &[u64]) -> u64 {
    let bytes: Vec<[u8; 8]> = words.iter().map(|w| w.to_le_bytes()).collect();
    let parts: Vec<&[u8]> = bytes.iter().map(|b| b.as_slice()).collect();
    sha256_u64(&parts)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hex_is_two_lower_case_digits_a_byte() {
        assert_eq!(hex(&[]), "");
        assert_eq!(hex(&[0, 1, 0xab, 0xff]), "0001abff");
    }

    #[test]
    fn sha256_hex_matches_the_standard_test_vector() {
        assert_eq!(
            sha256_hex(b"abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }

    #[test]
    fn u64_seeds_are_the_digest_prefix_little_endian_and_ignore_part_boundaries() {
        // SHA-256("abc") starts ba 78 16 bf 8f 01 cf ea.
        assert_eq!(sha256_u64(&[b"abc"]), 0xEACF_018F_BF16_78BA);
        assert_eq!(sha256_u64(&[b"a", b"bc"]), sha256_u64(&[b"abc"]));
        let mut bytes = 7u64.to_le_bytes().to_vec();
        bytes.extend(9u64.to_le_bytes());
        assert_eq!(words_u64(&[7, 9]), sha256_u64(&[&bytes]));
    }
}
