//! The identities and times the service speaks in, so that a job id is never passed where a schedule
//! id or an owner belongs, and a time is never confused with a count.

use serde::{Deserialize, Serialize};
use std::fmt;

/// Declares a string identity: built from any text (a path segment or a stored row may name
/// something that does not exist; the store says so), generated as a UUID v4 for new things. Text
/// that is a UUID is read in its canonical form, lowercase and hyphenated, since UUIDs are
/// case-insensitive on input (RFC 9562): `E0B5...` names the job `e0b5...`.
macro_rules! text_id {
    ($(#[$doc:meta])* $name:ident) => {
        $(#[$doc])*
        #[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
        #[serde(transparent)]
        pub struct $name(String);

        impl<'de> Deserialize<'de> for $name {
            fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
                String::deserialize(deserializer).map(Self::from)
            }
        }

        impl $name {
            /// A fresh, unique id.
            pub fn generate() -> Self {
                Self(uuid::Uuid::new_v4().to_string())
            }

            pub fn as_str(&self) -> &str {
                &self.0
            }
        }

        impl From<String> for $name {
            fn from(text: String) -> Self {
                match uuid::Uuid::try_parse(&text) {
                    Ok(uuid) => Self(uuid.hyphenated().to_string()),
                    Err(_) => Self(text),
                }
            }
        }

        impl From<&str> for $name {
            fn from(text: &str) -> Self {
                Self::from(text.to_owned())
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(&self.0)
            }
        }
    };
}

text_id!(
    /// A job: a UUID v4 made at submission.
    JobId
);
text_id!(
    /// A schedule: a UUID v4 made at creation.
    ScheduleId
);

/// Whose a job or schedule is: the SHA-256 (hex) of the caller's API key, or `""` on a server
/// without keys. Another owner's things are invisible, as if they did not exist.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Default)]
pub struct Owner(String);

impl Owner {
    /// The one owner of a server without API keys.
    pub fn anonymous() -> Self {
        Self(String::new())
    }

    /// The owner of a key: its SHA-256, so that keys themselves are never kept.
    pub fn of_key(key: &str) -> Self {
        use sha2::{Digest, Sha256};
        Self(
            Sha256::digest(key.as_bytes())
                .iter()
                .map(|b| format!("{b:02x}"))
                .collect(),
        )
    }

    /// An owner as stored.
    pub fn from_stored(hash: String) -> Self {
        Self(hash)
    }

    pub fn as_str(&self) -> &str {
        &self.0
    }
}

/// The fencing token of a job: bumped at every claim, and carried by every later write of that
/// claim, so that a worker whose lease expired can never overwrite its successor's work.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct Attempt(pub i64);

/// A moment, in milliseconds since the Unix epoch (how every time is stored).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct UnixMs(pub i64);

impl UnixMs {
    pub fn now() -> Self {
        Self(chrono::Utc::now().timestamp_millis())
    }

    pub fn from_datetime(time: chrono::DateTime<chrono::Utc>) -> Self {
        Self(time.timestamp_millis())
    }

    pub fn to_datetime(self) -> chrono::DateTime<chrono::Utc> {
        chrono::DateTime::from_timestamp_millis(self.0).unwrap_or_default()
    }

    /// RFC 3339 in UTC with milliseconds, as every time appears in the API.
    pub fn to_rfc3339(self) -> String {
        self.to_datetime()
            .to_rfc3339_opts(chrono::SecondsFormat::Millis, true)
    }

    /// `millis` later (saturating).
    pub fn plus_ms(self, millis: i64) -> Self {
        Self(self.0.saturating_add(millis))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_uuid_in_any_case_names_the_same_id_and_other_text_stays_as_it_is() {
        let id = JobId::generate();
        let upper = id.as_str().to_uppercase();
        assert_eq!(JobId::from(upper.as_str()), id);
        let read: ScheduleId = serde_json::from_str(&format!("\"{upper}\"")).unwrap();
        assert_eq!(read.as_str(), id.as_str());
        assert_eq!(JobId::from("Nightly-1").as_str(), "Nightly-1");
    }

    #[test]
    fn an_owner_is_the_sha256_of_its_key() {
        // sha256("abc"), FIPS 180-2 appendix B.1
        assert_eq!(
            Owner::of_key("abc").as_str(),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }

    #[test]
    fn times_read_as_rfc3339_with_milliseconds_in_utc() {
        assert_eq!(UnixMs(0).to_rfc3339(), "1970-01-01T00:00:00.000Z");
        assert_eq!(
            UnixMs(1_795_000_000_123).to_rfc3339(),
            "2026-11-18T11:06:40.123Z"
        );
    }
}
