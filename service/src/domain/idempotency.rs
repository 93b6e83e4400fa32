//! `Idempotency-Key`: a POST retried with the same key and body gets what its first attempt
//! created, for 24 hours, instead of creating it twice.

use super::UnixMs;
use sha2::{Digest, Sha256};

/// How long a key is remembered.
pub const KEY_LIFETIME_MS: i64 = 24 * 3600 * 1000;

/// A POST's key with the fingerprint of its body.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IdempotencyKey {
    pub key: String,
    /// SHA-256 (hex) of the body's bytes: the same key with another body is refused.
    pub fingerprint: String,
}

impl IdempotencyKey {
    /// The header's value: 1 to 255 visible ASCII characters.
    pub fn new(key: &str, body: &str) -> Result<Self, String> {
        if key.is_empty() || key.len() > 255 || !key.bytes().all(|b| b.is_ascii_graphic()) {
            return Err("Idempotency-Key must be 1 to 255 visible ASCII characters".to_owned());
        }
        Ok(Self {
            key: key.to_owned(),
            fingerprint: Sha256::digest(body.as_bytes())
                .iter()
                .map(|b| format!("{b:02x}"))
                .collect(),
        })
    }

    /// Keys used before this, seen at `now`, are forgotten.
    pub fn expired_before(now: UnixMs) -> UnixMs {
        UnixMs(now.0 - KEY_LIFETIME_MS)
    }
}

/// What a POST with a key did.
#[derive(Debug, Clone, PartialEq)]
pub enum Once<T> {
    /// The first use of the key: the resource is new.
    Created(T),
    /// A retry: the resource the key's first use created.
    Replayed(T),
    /// The key was used with another body.
    KeyReused,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_key_is_visible_ascii_and_its_fingerprint_follows_the_body() {
        let a = IdempotencyKey::new("k-1", "{}").unwrap();
        assert_eq!(a, IdempotencyKey::new("k-1", "{}").unwrap());
        assert_ne!(
            a.fingerprint,
            IdempotencyKey::new("k-1", "{ }").unwrap().fingerprint
        );
        for bad in ["", "with space", "é", &"x".repeat(256)] {
            assert!(IdempotencyKey::new(bad, "{}").is_err(), "{bad}");
        }
    }
}
