//! Input errors that name their field: a JSON pointer (RFC 6901) and the rule it broke.

use serde::Serialize;
use serde::de::DeserializeOwned;
use std::fmt;

/// A JSON pointer into a submitted document, built one reference token at a time.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Pointer(String);

impl Pointer {
    /// The whole document, `""`.
    pub fn root() -> Self {
        Self(String::new())
    }

    /// The member `name` (or array index) below this pointer, escaped as RFC 6901 requires.
    pub fn child(&self, name: impl fmt::Display) -> Self {
        let token = name.to_string().replace('~', "~0").replace('/', "~1");
        Self(format!("{}/{token}", self.0))
    }

    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl fmt::Display for Pointer {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

/// One field that broke one rule.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct FieldError {
    /// JSON pointer to the offending value (`""` is the whole document).
    pub pointer: String,
    /// The rule, in words, with the value that broke it.
    pub detail: String,
}

impl fmt::Display for FieldError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let pointer = if self.pointer.is_empty() {
            "(document)"
        } else {
            &self.pointer
        };
        write!(f, "{pointer}: {}", self.detail)
    }
}

/// Why a document cannot be used, fixed where the error is made: the fix differs (rewrite the text
/// or change a value), and HTTP tells the two apart (400 or 422).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InputErrorKind {
    /// The text is not JSON at all.
    Malformed,
    /// JSON that breaks a rule: a wrong type, an unknown field, a value out of range.
    Rule,
}

/// A submitted document that cannot be used, with every field at fault.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub struct InvalidInput {
    kind: InputErrorKind,
    errors: Vec<FieldError>,
}

impl InvalidInput {
    /// Rules broken, at least one; an empty list would be a bug in the caller.
    pub fn new(errors: Vec<FieldError>) -> Self {
        debug_assert!(!errors.is_empty());
        Self {
            kind: InputErrorKind::Rule,
            errors,
        }
    }

    /// Text that is not JSON: one error naming the whole document.
    fn malformed(detail: String) -> Self {
        Self {
            kind: InputErrorKind::Malformed,
            ..Self::single(&Pointer::root(), detail)
        }
    }

    pub fn single(pointer: &Pointer, detail: impl Into<String>) -> Self {
        Self::new(vec![FieldError {
            pointer: pointer.to_string(),
            detail: detail.into(),
        }])
    }

    /// The pointers of the fields at fault, in order.
    pub fn pointers(&self) -> Vec<&str> {
        self.errors.iter().map(|e| e.pointer.as_str()).collect()
    }

    pub fn errors(&self) -> &[FieldError] {
        &self.errors
    }

    pub fn kind(&self) -> InputErrorKind {
        self.kind
    }

    /// Whether the document was not JSON at all (as opposed to JSON that breaks a rule).
    pub fn is_syntax(&self) -> bool {
        self.kind == InputErrorKind::Malformed
    }
}

impl fmt::Display for InvalidInput {
    /// One line: every error, separated by `; `.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, error) in self.errors.iter().enumerate() {
            if i > 0 {
                f.write_str("; ")?;
            }
            write!(f, "{error}")?;
        }
        Ok(())
    }
}

/// Deserialises a JSON document, turning a serde failure into an [`InvalidInput`] whose pointer
/// names the field where it happened (unknown field, wrong type, out-of-range integer) or the whole
/// document for a syntax error.
///
/// serde's derived structs also accept a JSON array of their fields in order; a user who writes
/// `"circuit": [48, 15]` made a mistake, so arrays are rejected everywhere except at the pointers in
/// `array_fields` (the document's real lists).
pub fn from_json<T: DeserializeOwned>(
    text: &str,
    array_fields: &[&str],
) -> Result<T, InvalidInput> {
    let value: serde_json::Value =
        serde_json::from_str(text).map_err(|error| invalid_from_serde(Pointer::root(), &error))?;
    reject_misplaced_arrays(&value, &Pointer::root(), array_fields)?;
    serde_path_to_error::deserialize(value).map_err(|error| {
        let pointer = path_to_pointer(error.path());
        invalid_from_serde(pointer, error.inner())
    })
}

fn reject_misplaced_arrays(
    value: &serde_json::Value,
    at: &Pointer,
    array_fields: &[&str],
) -> Result<(), InvalidInput> {
    match value {
        serde_json::Value::Array(items) => {
            if !array_fields.contains(&at.as_str()) {
                return Err(InvalidInput::single(
                    at,
                    "expected an object or a number, found an array",
                ));
            }
            items
                .iter()
                .enumerate()
                .try_for_each(|(i, item)| reject_misplaced_arrays(item, &at.child(i), array_fields))
        }
        serde_json::Value::Object(members) => members.iter().try_for_each(|(name, member)| {
            reject_misplaced_arrays(member, &at.child(name), array_fields)
        }),
        _ => Ok(()),
    }
}

fn invalid_from_serde(pointer: Pointer, error: &serde_json::Error) -> InvalidInput {
    use serde_json::error::Category;
    match error.classify() {
        Category::Syntax | Category::Eof | Category::Io => {
            InvalidInput::malformed(format!("malformed JSON: {error}"))
        }
        Category::Data => InvalidInput::single(&pointer, error.to_string()),
    }
}

fn path_to_pointer(path: &serde_path_to_error::Path) -> Pointer {
    use serde_path_to_error::Segment;
    path.iter()
        .fold(Pointer::root(), |pointer, segment| match segment {
            Segment::Seq { index } => pointer.child(index),
            Segment::Map { key } | Segment::Enum { variant: key } => pointer.child(key),
            Segment::Unknown => pointer,
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pointer_tokens_are_escaped() {
        assert_eq!(
            Pointer::root().child("a/b").child("m~n").child(3).as_str(),
            "/a~1b/m~0n/3"
        );
    }

    #[test]
    fn trailing_garbage_is_malformed() {
        let err = from_json::<serde_json::Value>("{} x", &[]).unwrap_err();
        assert!(err.is_syntax(), "{err}");
    }

    #[test]
    fn a_wrong_type_breaks_a_rule_not_the_syntax() {
        let err = from_json::<Vec<u64>>("[1, -1]", &[""]).unwrap_err();
        assert_eq!(err.kind(), InputErrorKind::Rule, "{err}");
    }

    #[test]
    fn a_rule_whose_words_start_like_a_syntax_error_is_still_a_rule() {
        let err = InvalidInput::single(&Pointer::root(), "malformed JSON: says the rule");
        assert!(!err.is_syntax());
    }
}
