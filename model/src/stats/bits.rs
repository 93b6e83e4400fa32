//! Floats serialised by their bits in human-readable formats (JSON): exact, and infinities and
//! NaNs included, which JSON numbers cannot carry. A binary format (the store's postcard) takes
//! the float itself, its eight bytes, which are its bits already.

use serde::{Deserialize, Deserializer, Serializer};

pub fn serialize<S: Serializer>(value: &f64, serializer: S) -> Result<S::Ok, S::Error> {
    if serializer.is_human_readable() {
        serializer.serialize_u64(value.to_bits())
    } else {
        serializer.serialize_f64(*value)
    }
}

pub fn deserialize<'de, D: Deserializer<'de>>(deserializer: D) -> Result<f64, D::Error> {
    if deserializer.is_human_readable() {
        u64::deserialize(deserializer).map(f64::from_bits)
    } else {
        f64::deserialize(deserializer)
    }
}

/// The same for an optional float.
pub mod optional {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(value: &Option<f64>, serializer: S) -> Result<S::Ok, S::Error> {
        match value {
            Some(value) if serializer.is_human_readable() => {
                serializer.serialize_some(&value.to_bits())
            }
            Some(value) => serializer.serialize_some(value),
            None => serializer.serialize_none(),
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(
        deserializer: D,
    ) -> Result<Option<f64>, D::Error> {
        if deserializer.is_human_readable() {
            Option::<u64>::deserialize(deserializer).map(|bits| bits.map(f64::from_bits))
        } else {
            Option::<f64>::deserialize(deserializer)
        }
    }
}

/// The same for a list of floats.
pub mod list {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(values: &[f64], serializer: S) -> Result<S::Ok, S::Error> {
        serialize_joined(values, &[], serializer)
    }

    /// The list of `first`'s values then `second`'s, written as [`serialize`] writes it, without
    /// gathering it into one.
    pub fn serialize_joined<S: Serializer>(
        first: &[f64],
        second: &[f64],
        serializer: S,
    ) -> Result<S::Ok, S::Error> {
        let values = first.iter().chain(second);
        if serializer.is_human_readable() {
            serializer.collect_seq(values.map(|value| value.to_bits()))
        } else {
            serializer.collect_seq(values)
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(deserializer: D) -> Result<Vec<f64>, D::Error> {
        if deserializer.is_human_readable() {
            Vec::<u64>::deserialize(deserializer)
                .map(|bits| bits.into_iter().map(f64::from_bits).collect())
        } else {
            Vec::<f64>::deserialize(deserializer)
        }
    }
}
