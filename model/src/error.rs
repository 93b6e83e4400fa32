//! Input errors that name their field: a JSON pointer (RFC 6901) and the rule it broke.

use serde::Serialize;
use serde::de::DeserializeOwned;
use serde_path_to_error::Segment;
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

/// The most faults an error lists. A document of a megabyte can break a rule in every item of a
/// list (200,000 unknown metric names once made an answer of 145 MB, and 758 MB of the server's
/// memory); a check of a user's list stops once more than this many are found.
pub const MAX_LISTED_FAULTS: usize = 50;

/// Whether `errors` holds more faults than an error lists: a check of a user's list stops there.
pub fn past_listing(errors: &[FieldError]) -> bool {
    errors.len() > MAX_LISTED_FAULTS
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
    /// Rules broken, at least one (an empty list would be a bug in the caller); past
    /// [`MAX_LISTED_FAULTS`], the rest are left out and a last entry says so.
    pub fn new(mut errors: Vec<FieldError>) -> Self {
        debug_assert!(!errors.is_empty());
        if errors.len() > MAX_LISTED_FAULTS {
            errors.truncate(MAX_LISTED_FAULTS);
            errors.push(FieldError {
                pointer: String::new(),
                detail: format!(
                    "more faults than the {MAX_LISTED_FAULTS} listed: mend these and send it again"
                ),
            });
        }
        Self {
            kind: InputErrorKind::Rule,
            errors,
        }
    }

    /// Text that is not JSON: one error, at the value the reader was in when the text stopped
    /// being JSON (a `NaN` or `0x10` given for a field names that field; the whole document
    /// otherwise).
    fn malformed(pointer: &Pointer, detail: String) -> Self {
        Self {
            kind: InputErrorKind::Malformed,
            ..Self::single(pointer, detail)
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
pub fn from_json<T: DeserializeOwned + Serialize>(
    text: &str,
    array_fields: &[&str],
) -> Result<T, InvalidInput> {
    let (value, faults) = read_past_faults(text, array_fields)?;
    with_faults(faults, Ok(value))
}

/// The most members [`read_past_faults`] leaves out before it stops.
pub const MAX_FAULTS: usize = 20;

/// The text [`read_past_faults`] reads in all, its readings counted whole: a small document is
/// read past up to [`MAX_FAULTS`] faults, a large one fewer times (a body of 1 MiB, the
/// service's largest by default, four times), so that a hostile document costs a few readings.
pub const READ_PAST_BYTES: usize = 4 << 20;

/// [`from_json`], read on past the members serde cannot take, so that every field at fault is
/// named, not only the first: a member of an object whose value has the wrong type or range, or
/// which the object does not know, is named and left out, and the document read again (up to
/// [`MAX_FAULTS`] times, fewer for a large document: [`READ_PAST_BYTES`]). The value read
/// without them comes back with the faults, for the caller's own rules to check the rest
/// ([`with_faults`]). A fault it cannot leave out (a missing field, an item of a list, the whole
/// document), or one in an object it left a member out of, ends the reading: the faults so far
/// are the error. So does one more after the last reading, with a last entry at `""` saying so.
/// A name written as an object (`{"exact": null}`) is a fault at the name.
pub fn read_past_faults<T: DeserializeOwned + Serialize>(
    text: &str,
    array_fields: &[&str],
) -> Result<(T, Vec<FieldError>), InvalidInput> {
    let mut value = read_strict(text)?;
    let readings = (READ_PAST_BYTES / text.len().max(1)).clamp(1, MAX_FAULTS);
    let mut faults: Vec<FieldError> = Vec::new();
    // The members left out, by the object they were left out of: a later fault there is the
    // leaving out's own (an object left empty, the field left out now missing), not another; a
    // field missing that was never there (beside an unknown member) is a fault of its own.
    let mut left_out: Vec<(String, String)> = Vec::new();
    let mut shape = Vec::new();
    let unreadable = check_shape(&value, &Pointer::root(), array_fields, &mut shape).err();
    // A list in a member's place is left out as a member of the wrong type is (below).
    for at in shape {
        if faults.len() >= readings {
            faults.push(stopped_reading(readings));
            return Err(InvalidInput::new(faults));
        }
        let (parent, member) = at.as_str().rsplit_once('/').unwrap_or(("", ""));
        let member = unescape(member);
        if let Some(members) = value.pointer_mut(parent).and_then(|v| v.as_object_mut()) {
            members.remove(&member);
        }
        faults.push(FieldError {
            pointer: at.to_string(),
            detail: LIST_IN_A_MEMBERS_PLACE.to_owned(),
        });
        left_out.push((parent.to_owned(), member));
    }
    if let Some(unreadable) = unreadable {
        faults.extend(unreadable.errors);
        return Err(InvalidInput::new(faults));
    }
    loop {
        let error = match serde_path_to_error::deserialize(&value) {
            Ok(read) => {
                if let Ok(back) = serde_json::to_value(&read) {
                    named_as_objects(&value, &back, &Pointer::root(), &mut faults);
                }
                return Ok((read, faults));
            }
            Err(error) => error,
        };
        let mut segments: Vec<&Segment> = error.path().iter().collect();
        let detail = error.inner().to_string();
        let name_as_object = detail.ends_with("expected unit")
            && matches!(segments.last(), Some(Segment::Enum { .. }));
        if name_as_object {
            // `{"closed_form": {}}` where a name is asked: named where the name belongs.
            segments.pop();
        }
        let pointer = path_to_pointer(&segments);
        let at = pointer.to_string();
        let consequence = match detail
            .strip_prefix("missing field `")
            .and_then(|rest| rest.split_once('`'))
        {
            Some((field, _)) => left_out
                .iter()
                .any(|(object, member)| *object == at && member == field),
            None => left_out.iter().any(|(object, _)| *object == at),
        };
        if name_as_object {
            faults.push(name_as_object_at(at.clone()));
        } else if !consequence {
            faults.extend(invalid_from_serde(pointer, error.inner()).errors);
        }
        let removable = !consequence && !detail.starts_with("missing field");
        if removable && faults.len() >= readings {
            // Read past as often as it may be: the rest of the document is unread, and the list
            // says so rather than look whole.
            faults.push(stopped_reading(readings));
            return Err(InvalidInput::new(faults));
        }
        if !(removable && leave_out(&mut value, &segments)) {
            return Err(InvalidInput::new(faults));
        }
        let (parent, member) = at.rsplit_once('/').unwrap_or(("", ""));
        left_out.push((parent.to_owned(), unescape(member)));
    }
}

/// The last entry of a list of faults read past as often as they may be.
fn stopped_reading(readings: usize) -> FieldError {
    FieldError {
        pointer: String::new(),
        detail: format!(
            "read past {readings} faults and stopped: the rest of the document is not checked \
             yet; mend these and send it again"
        ),
    }
}

/// A JSON pointer's token as the member name it stands for (RFC 6901: `~1` is `/`, `~0` is `~`).
fn unescape(token: &str) -> String {
    token.replace("~1", "/").replace("~0", "~")
}

/// A name written as an object: serde reads `{"exact": null}` as `"exact"` (an enum's
/// one-member form, which no document states) and refuses `{"closed_form": {}}` as `expected
/// unit`, below a member the document does not have.
const NAME_AS_OBJECT: &str = "invalid type: object, expected text (one of its names)";

/// The fault of a name written as an object at `pointer`.
fn name_as_object_at(pointer: String) -> FieldError {
    FieldError {
        pointer,
        detail: NAME_AS_OBJECT.to_owned(),
    }
}

/// Every place where `written` has an object and `read` (the value read from it, written back)
/// has text: a name given in serde's one-member form, for [`NAME_AS_OBJECT`].
fn named_as_objects(
    written: &serde_json::Value,
    read: &serde_json::Value,
    at: &Pointer,
    faults: &mut Vec<FieldError>,
) {
    use serde_json::Value;
    if past_listing(faults) {
        return;
    }
    match (written, read) {
        (Value::Object(_), Value::String(_)) => faults.push(name_as_object_at(at.to_string())),
        (Value::Object(written), Value::Object(read)) => {
            for (name, member) in written {
                if let Some(back) = read.get(name) {
                    named_as_objects(member, back, &at.child(name), faults);
                }
            }
        }
        (Value::Array(written), Value::Array(read)) if written.len() == read.len() => {
            for (i, (item, back)) in written.iter().zip(read).enumerate() {
                named_as_objects(item, back, &at.child(i), faults);
            }
        }
        _ => {}
    }
}

/// Removes the object member `segments` name from `value`; whether there was one to remove (an
/// item of a list is kept: removing it would renumber the items after it).
fn leave_out(value: &mut serde_json::Value, segments: &[&Segment]) -> bool {
    let Some((Segment::Map { key }, parents)) = segments.split_last() else {
        return false;
    };
    let mut at = value;
    for segment in parents {
        let next = match (segment, at) {
            (
                Segment::Map { key } | Segment::Enum { variant: key },
                serde_json::Value::Object(m),
            ) => m.get_mut(key.as_str()),
            (Segment::Seq { index }, serde_json::Value::Array(items)) => items.get_mut(*index),
            _ => None,
        };
        match next {
            Some(next) => at = next,
            None => return false,
        }
    }
    match at {
        serde_json::Value::Object(members) => members.remove(key.as_str()).is_some(),
        _ => false,
    }
}

/// `checked` (the caller's own rules, applied to what [`read_past_faults`] read), with the
/// `faults` met on the way before its own.
pub fn with_faults<T>(
    faults: Vec<FieldError>,
    checked: Result<T, InvalidInput>,
) -> Result<T, InvalidInput> {
    match (faults.is_empty(), checked) {
        (true, checked) => checked,
        (false, Ok(_)) => Err(InvalidInput::new(faults)),
        (false, Err(invalid)) => {
            // A rule broken at a member's ancestor (an observation with nothing measured, once
            // its one measured value of the wrong type was left out) follows from the fault
            // there: said once, at the member. A name written as an object was read as the name,
            // so the rules above it stand on their own.
            let follows = |rule: &FieldError| {
                faults.iter().any(|fault| {
                    fault.detail != NAME_AS_OBJECT
                        && fault.pointer.starts_with(&rule.pointer)
                        && fault.pointer[rule.pointer.len()..].starts_with('/')
                })
            };
            let rules: Vec<FieldError> = invalid
                .errors
                .into_iter()
                .filter(|rule| !follows(rule))
                .collect();
            let mut errors = faults;
            errors.extend(rules);
            Err(InvalidInput::new(errors))
        }
    }
}

/// A document's bytes that are not UTF-8, as a malformed document whose pointer names the value
/// where the text stopped being JSON: the value the first byte that is not UTF-8 falls in (a
/// JSON text is UTF-8, RFC 8259 section 8.1).
pub fn not_utf8(bytes: &[u8], error: &std::str::Utf8Error) -> InvalidInput {
    let at = error.valid_up_to();
    let text = std::str::from_utf8(&bytes[..at]).expect("valid up to there");
    let detail = format!(
        "malformed JSON: the text is not UTF-8 at byte {at} (0x{:02X})",
        bytes[at]
    );
    // The valid text ends inside that value: reading it stops there, and names it.
    match read_strict(text) {
        Err(mut invalid) => {
            invalid.kind = InputErrorKind::Malformed;
            invalid.errors.truncate(1);
            invalid.errors[0].detail = detail;
            invalid
        }
        Ok(_) => InvalidInput::malformed(&Pointer::root(), detail),
    }
}

/// Reads JSON text into a value, naming by pointer what the text itself gets wrong where a value
/// is at fault: a number beyond f64 (`1e400`) and a member given twice in one object (which
/// serde_json would silently resolve to the last). Other syntax errors name the whole document.
fn read_strict(text: &str) -> Result<serde_json::Value, InvalidInput> {
    let mut reader = serde_json::Deserializer::from_str(text);
    let Strict(value) = serde_path_to_error::deserialize(&mut reader).map_err(|error| {
        let segments: Vec<&Segment> = error.path().iter().collect();
        let (pointer, inner) = (path_to_pointer(&segments), error.inner());
        // serde_json calls an overflowing number a syntax error, but the text is JSON: only the
        // value cannot be represented, so it breaks a rule at its field.
        if inner.to_string().starts_with("number out of range") {
            InvalidInput::single(
                &pointer,
                format!("{inner}: a number's magnitude must stay below 1.8e308"),
            )
        } else {
            invalid_from_serde(pointer, inner)
        }
    })?;
    reader
        .end()
        .map_err(|error| invalid_from_serde(Pointer::root(), &error))?;
    if let Some((pointer, token)) = underflowing_number(text) {
        return Err(InvalidInput::single(&pointer, underflow(&token)));
    }
    Ok(value)
}

/// Why `token`, a number written as not 0 that reads as 0 (`1e-400`), is refused, in a body or a
/// query.
pub fn underflow(token: &str) -> String {
    format!(
        "`{token}` is not 0, but nearer 0 than any number (the least is 4.9e-324) and would read \
         as 0: write 0, or a number within range"
    )
}

/// The first number of valid JSON `text` written as not zero that reads as 0 (`1e-400`, which
/// serde_json rounds to 0 without a word: a positive field would have taken it as 0), with its
/// pointer.
fn underflowing_number(text: &str) -> Option<(Pointer, String)> {
    /// Where the scan is: an object with the member being read, or a list at an index.
    enum At {
        Object(Option<String>),
        List(usize),
    }
    let pointer = |stack: &[At]| {
        stack.iter().fold(Pointer::root(), |pointer, at| match at {
            At::Object(Some(member)) => pointer.child(member),
            At::Object(None) => pointer,
            At::List(index) => pointer.child(index),
        })
    };
    let bytes = text.as_bytes();
    let mut stack: Vec<At> = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        match bytes[i] {
            b'{' => stack.push(At::Object(None)),
            b'[' => stack.push(At::List(0)),
            b'}' | b']' => {
                stack.pop();
            }
            b',' => {
                if let Some(At::List(index)) = stack.last_mut() {
                    *index += 1;
                }
            }
            b'"' => {
                let mut end = i + 1;
                while bytes[end] != b'"' {
                    end += if bytes[end] == b'\\' { 2 } else { 1 };
                }
                let rest = text[end + 1..].trim_start();
                if let (Some(At::Object(member)), true) = (stack.last_mut(), rest.starts_with(':'))
                {
                    *member = serde_json::from_str(&text[i..=end]).ok();
                }
                i = end;
            }
            b'-' | b'0'..=b'9' => {
                let end = text[i..]
                    .find(|c: char| !matches!(c, '-' | '+' | '.' | 'e' | 'E' | '0'..='9'))
                    .map_or(text.len(), |n| i + n);
                let token = &text[i..end];
                let mantissa = token.split(['e', 'E']).next().unwrap_or("");
                if mantissa.contains(|c: char| matches!(c, '1'..='9'))
                    && token.parse::<f64>().is_ok_and(|value| value == 0.0)
                {
                    return Some((pointer(&stack), token.to_owned()));
                }
                i = end - 1;
            }
            _ => {}
        }
        i += 1;
    }
    None
}

/// A JSON value whose objects name each member once.
struct Strict(serde_json::Value);

impl<'de> serde::Deserialize<'de> for Strict {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        deserializer.deserialize_any(StrictVisitor).map(Strict)
    }
}

struct StrictVisitor;

impl<'de> serde::de::Visitor<'de> for StrictVisitor {
    type Value = serde_json::Value;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a JSON value")
    }

    fn visit_bool<E>(self, value: bool) -> Result<Self::Value, E> {
        Ok(value.into())
    }

    fn visit_i64<E>(self, value: i64) -> Result<Self::Value, E> {
        Ok(value.into())
    }

    fn visit_u64<E>(self, value: u64) -> Result<Self::Value, E> {
        Ok(value.into())
    }

    /// A number written with a fraction or exponent but integral (`2.0`, `1e3`) is an integer, as
    /// JSON Schema counts it: it may fill an integer field. Only below 2^53 in magnitude, where
    /// every integer has its own f64: from there, the number read may not be the one written
    /// (`12345678901234567.5` reads as 12345678901234568, `9007199254740993.0` as ...992), so it
    /// stays a fraction, and an integer field there takes digits alone.
    fn visit_f64<E>(self, value: f64) -> Result<Self::Value, E> {
        const TWO_TO_53: f64 = 9_007_199_254_740_992.0;
        Ok(if value.fract() != 0.0 || value.abs() >= TWO_TO_53 {
            value.into()
        } else if value >= 0.0 {
            (value as u64).into()
        } else {
            (value as i64).into()
        })
    }

    fn visit_str<E>(self, value: &str) -> Result<Self::Value, E> {
        Ok(value.into())
    }

    fn visit_string<E>(self, value: String) -> Result<Self::Value, E> {
        Ok(value.into())
    }

    fn visit_unit<E>(self) -> Result<Self::Value, E> {
        Ok(serde_json::Value::Null)
    }

    fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        let mut items = Vec::new();
        while let Some(Strict(item)) = seq.next_element()? {
            items.push(item);
        }
        Ok(items.into())
    }

    fn visit_map<A: serde::de::MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
        let mut members = serde_json::Map::new();
        while let Some(name) = map.next_key::<String>()? {
            if members.contains_key(&name) {
                // Failing as the member's value puts its name in the error's path.
                return map.next_value_seed(GivenTwice);
            }
            let Strict(value) = map.next_value()?;
            members.insert(name, value);
        }
        Ok(members.into())
    }
}

/// The value of a member its object already has: refused.
struct GivenTwice;

impl<'de> serde::de::DeserializeSeed<'de> for GivenTwice {
    type Value = serde_json::Value;

    fn deserialize<D: serde::Deserializer<'de>>(self, _: D) -> Result<Self::Value, D::Error> {
        Err(serde::de::Error::custom(
            "is given twice in its object; give each member once",
        ))
    }
}

/// A number as an error message shows it: as Rust writes it (the shortest text that reads back to
/// it), but in exponent form where that would be a long run of digits (`-1e308` is 309 of them).
pub fn shown(x: f64) -> String {
    let magnitude = x.abs();
    if magnitude != 0.0 && !(1e-5..1e16).contains(&magnitude) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

/// The most characters any text in a document may have: a name, a label, a cron expression, a
/// metric's name, and the name of any member. Longer text is never a mistake worth storing.
pub const MAX_TEXT_CHARS: usize = 200;

/// Why text may not hold U+0000 (NUL), in a document or a URL's path: PostgreSQL stores no such
/// character (a job named with one got 503 there, and was stored on SQLite), and no name has one.
pub const NO_NUL: &str = "must not hold the character U+0000 (NUL)";

/// Whether `pointer` is the list field `field`, in which a `*` token stands for any index or
/// member name (`/correlation/matrix/*`: each row of a matrix; `/limits/*`: any metric's list).
fn matches_field(field: &str, pointer: &str) -> bool {
    let (mut field, mut pointer) = (field.split('/'), pointer.split('/'));
    loop {
        match (field.next(), pointer.next()) {
            (None, None) => return true,
            (Some(f), Some(p)) if f == p || f == "*" => {}
            _ => return false,
        }
    }
}

/// Why a list where the document has none, as an object's member, is left out.
const LIST_IN_A_MEMBERS_PLACE: &str =
    "expected one value here (an object, a number or text), found a list";

/// The rules every document's shape obeys before its types are read: arrays only where the
/// document has lists (`array_fields`), and no text longer than [`MAX_TEXT_CHARS`] or holding
/// U+0000 ([`NO_NUL`]). A list as an object's member where the document has none goes to
/// `lists` (members in the order of their names), to be read past; any other fault ends the
/// check.
fn check_shape(
    value: &serde_json::Value,
    at: &Pointer,
    array_fields: &[&str],
    lists: &mut Vec<Pointer>,
) -> Result<(), InvalidInput> {
    let text_error = |at: &Pointer, what: &str, text: &str| {
        if text.chars().count() > MAX_TEXT_CHARS {
            let rule = format!("{what} must be at most {MAX_TEXT_CHARS} characters");
            Err(InvalidInput::single(at, rule))
        } else if text.contains('\0') {
            Err(InvalidInput::single(at, format!("{what} {NO_NUL}")))
        } else {
            Ok(())
        }
    };
    match value {
        serde_json::Value::Array(items) => {
            if !array_fields
                .iter()
                .any(|field| matches_field(field, at.as_str()))
            {
                // Every document is an object; within one, the type asked depends on the field.
                let expected = if at.as_str().is_empty() {
                    "expected an object, found a list"
                } else {
                    LIST_IN_A_MEMBERS_PLACE
                };
                return Err(InvalidInput::single(at, expected));
            }
            items
                .iter()
                .enumerate()
                .try_for_each(|(i, item)| check_shape(item, &at.child(i), array_fields, lists))
        }
        serde_json::Value::Object(members) => members.iter().try_for_each(|(name, member)| {
            let at = at.child(name);
            text_error(&at, "a member's name", name)?;
            let misplaced = member.is_array()
                && !array_fields
                    .iter()
                    .any(|field| matches_field(field, at.as_str()));
            if misplaced {
                lists.push(at);
                Ok(())
            } else {
                check_shape(member, &at, array_fields, lists)
            }
        }),
        serde_json::Value::String(text) => text_error(at, "text", text),
        _ => Ok(()),
    }
}

fn invalid_from_serde(pointer: Pointer, error: &serde_json::Error) -> InvalidInput {
    use serde_json::error::Category;
    match error.classify() {
        Category::Syntax | Category::Eof | Category::Io => {
            InvalidInput::malformed(&pointer, format!("malformed JSON: {error}"))
        }
        Category::Data => {
            let message = in_plain_words(&error.to_string());
            // A missing field is named by its own pointer, not its object's.
            let missing = message
                .strip_prefix("missing field `")
                .and_then(|rest| rest.split_once('`'))
                .map(|(field, _)| pointer.child(field));
            InvalidInput::single(missing.as_ref().unwrap_or(&pointer), message)
        }
    }
}

/// serde's message with the Rust types it names (`expected f64`, `expected u64`, `expected
/// struct CircuitSpec`) put as a JSON document's reader knows them.
fn in_plain_words(message: &str) -> String {
    // A whole number's range here is its type's, the most it can be read as (a seed's whole
    // rule); a field's own rule, where narrower, is said where it is checked.
    const TYPES: [(&str, &str); 18] = [
        // An object of no or several members where a name is asked (serde's one-member form of
        // an enum's name aside): before `expected map` below takes its words.
        (
            "invalid value: map, expected map with a single key",
            NAME_AS_OBJECT,
        ),
        ("expected f64", "expected a number"),
        ("expected f32", "expected a number"),
        (
            "expected u64",
            "expected a whole number from 0 to 18446744073709551615",
        ),
        (
            "expected usize",
            "expected a whole number from 0 to 18446744073709551615",
        ),
        (
            "expected u32",
            "expected a whole number from 0 to 4294967295",
        ),
        ("expected u16", "expected a whole number from 0 to 65535"),
        ("expected u8", "expected a whole number from 0 to 255"),
        (
            "expected i64",
            "expected a whole number from -9223372036854775808 to 9223372036854775807",
        ),
        ("expected a sequence", "expected a list"),
        ("expected a map", "expected an object"),
        ("expected map", "expected an object"),
        ("invalid type: map", "invalid type: object"),
        ("invalid type: sequence", "invalid type: list"),
        ("invalid type: floating point", "invalid type: number"),
        (
            "expected variant identifier",
            "expected one of its names (text)",
        ),
        ("unknown variant", "unknown value"),
        // A name (an enum's unit variant): text, not serde's one-member object.
        ("expected string or map", "expected text (one of its names)"),
    ];
    let mut plain = message.to_owned();
    for (rust, json) in TYPES {
        if let Some(at) = plain.find(rust)
            && !plain[at + rust.len()..].starts_with(|c: char| c.is_alphanumeric())
        {
            plain.replace_range(at..at + rust.len(), json);
        }
    }
    // `expected struct CircuitSpec`: an object, whatever the Rust name of its type.
    if let Some(at) = plain.find("expected struct ") {
        let end = plain[at..]
            .find(|c: char| !(c.is_alphanumeric() || c == ' ' || c == '_'))
            .map_or(plain.len(), |n| at + n);
        plain.replace_range(at..end, "expected an object");
    }
    // A number read as one with a point or an exponent (`2.5`, `1e+20`, or a whole number beyond
    // the type, which JSON's reader takes as such): the number quoted may not be the one
    // written (`9007199254740993.0` is quoted `9007199254740992.0`).
    // `2.5` is no whole number however written: the hint is for those that are.
    let quoted = plain
        .strip_prefix("invalid type: number `")
        .and_then(|rest| rest.split_once('`'))
        .and_then(|(number, _)| number.parse::<f64>().ok());
    if let Some(number) = quoted.filter(|number| number.fract() == 0.0)
        && plain.contains("expected a whole number")
    {
        // Beyond every integer type (2^64 and up, below -2^63), however it is written: written
        // in digits, it was told to write it in digits (found from outside).
        plain.push_str(if (-(2f64.powi(63))..2f64.powi(64)).contains(&number) {
            ", written in digits alone"
        } else {
            ", and the one written lies beyond that range"
        });
    }
    plain
}

fn path_to_pointer(segments: &[&Segment]) -> Pointer {
    segments
        .iter()
        .fold(Pointer::root(), |pointer, segment| match segment {
            Segment::Seq { index } => pointer.child(index),
            Segment::Map { key } | Segment::Enum { variant: key } => pointer.child(key),
            Segment::Unknown => pointer,
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A required field missing beside an unknown member is a fault of its own (it was taken for
    /// the leaving out's consequence, and `{"bogus": 1}` named /bogus alone); the same field left
    /// out for its wrong type is not said missing again.
    #[test]
    fn a_missing_field_beside_an_unknown_member_is_named_too() {
        #[derive(Debug, serde::Deserialize, serde::Serialize)]
        #[serde(deny_unknown_fields)]
        #[allow(dead_code, reason = "only read")]
        struct Doc {
            fit: Vec<String>,
        }
        let named = |text: &str| -> Vec<String> {
            let invalid = from_json::<Doc>(text, &["/fit"]).unwrap_err();
            invalid.pointers().into_iter().map(str::to_owned).collect()
        };
        assert_eq!(named(r#"{"bogus": 1}"#), ["/bogus", "/fit"]);
        assert_eq!(named(r#"{"fit": 5}"#), ["/fit"]);
    }

    /// Messages name JSON's types, not Rust's: `/devices: invalid type: string "x", expected u64`
    /// told a user of a type they never wrote.
    #[test]
    fn a_wrong_type_is_told_in_jsons_words() {
        #[derive(Debug, serde::Deserialize, serde::Serialize)]
        #[allow(dead_code, reason = "only read")]
        struct Inner {
            x: f64,
        }
        #[derive(Debug, serde::Deserialize, serde::Serialize)]
        #[allow(dead_code, reason = "only read")]
        struct Doc {
            count: Option<u64>,
            small: Option<u32>,
            inner: Option<Inner>,
            value: Option<f64>,
            map: Option<std::collections::BTreeMap<String, f64>>,
        }
        for (text, expected) in [
            (
                r#"{"count": "x"}"#,
                r#"/count: invalid type: string "x", expected a whole number from 0 to 18446744073709551615"#,
            ),
            (
                r#"{"count": -1}"#,
                "/count: invalid value: integer `-1`, expected a whole number from 0 to 18446744073709551615",
            ),
            (
                r#"{"small": 1.5}"#,
                "/small: invalid type: number `1.5`, expected a whole number from 0 to 4294967295",
            ),
            (
                r#"{"count": 9007199254740993.0}"#,
                "/count: invalid type: number `9007199254740992.0`, expected a whole number from 0 to 18446744073709551615, written in digits alone",
            ),
            (
                r#"{"count": 18446744073709551616}"#,
                "/count: invalid type: number `1.8446744073709552e+19`, expected a whole number from 0 to 18446744073709551615, and the one written lies beyond that range",
            ),
            (
                r#"{"count": 100000000000000000000}"#,
                "/count: invalid type: number `1e+20`, expected a whole number from 0 to 18446744073709551615, and the one written lies beyond that range",
            ),
            (
                r#"{"map": 5}"#,
                "/map: invalid type: integer `5`, expected an object",
            ),
            (
                r#"{"inner": 3}"#,
                "/inner: invalid type: integer `3`, expected an object",
            ),
            (
                r#"{"value": "x"}"#,
                r#"/value: invalid type: string "x", expected a number"#,
            ),
            (
                r#"{"value": [1]}"#,
                "/value: expected one value here (an object, a number or text), found a list",
            ),
            ("[1, 2]", "(document): expected an object, found a list"),
        ] {
            let invalid = from_json::<Doc>(text, &[]).unwrap_err();
            assert_eq!(invalid.to_string(), expected);
        }
    }

    /// A name is text: serde also reads an enum's name in its one-member object form
    /// (`{"exact": null}` was taken as `"exact"`, `{"closed_form": {}}` refused below a member the
    /// document does not have, and a wrong type was told `expected string or map`). Each is
    /// named where the name belongs, and read past; a name in its place and an object of
    /// fields beside it are as before.
    #[test]
    fn a_name_is_text_not_an_object() {
        #[derive(Debug, PartialEq, serde::Deserialize, serde::Serialize)]
        #[serde(rename_all = "snake_case")]
        enum Kind {
            Exact,
            ClosedForm,
        }
        #[derive(Debug, serde::Deserialize, serde::Serialize)]
        #[serde(deny_unknown_fields)]
        struct Item {
            kind: Kind,
            #[serde(default)]
            size: u32,
        }
        #[derive(Debug, serde::Deserialize, serde::Serialize)]
        #[serde(deny_unknown_fields)]
        struct Doc {
            fidelity: Option<Kind>,
            #[serde(default)]
            items: Vec<Item>,
            count: Option<u64>,
        }
        let named = |text: &str| -> Vec<String> {
            match from_json::<Doc>(text, &["/items"]) {
                Ok(_) => Vec::new(),
                Err(invalid) => invalid.errors().iter().map(|e| e.to_string()).collect(),
            }
        };
        let object = "invalid type: object, expected text (one of its names)";
        assert_eq!(
            named(r#"{"fidelity": {"exact": null}}"#),
            [format!("/fidelity: {object}")]
        );
        assert_eq!(
            named(r#"{"fidelity": {"closed_form": {}}, "count": "x"}"#),
            [
                r#"/count: invalid type: string "x", expected a whole number from 0 to 18446744073709551615"#
                    .to_owned(),
                format!("/fidelity: {object}")
            ]
        );
        assert_eq!(
            named(r#"{"items": [{"kind": "exact"}, {"kind": {"closed_form": null}, "size": 2}]}"#),
            [format!("/items/1/kind: {object}")]
        );
        for empty_or_two in [r#"{}"#, r#"{"exact": null, "closed_form": null}"#] {
            assert_eq!(
                named(&format!(r#"{{"fidelity": {empty_or_two}}}"#)),
                [format!("/fidelity: {object}")]
            );
        }
        assert_eq!(
            named(r#"{"fidelity": null, "items": [{"kind": 5}]}"#),
            ["/items/0/kind: invalid type: integer `5`, expected text (one of its names)"]
        );
        let read: Doc = from_json(
            r#"{"fidelity": "closed_form", "items": [{"kind": "exact", "size": 3}]}"#,
            &["/items"],
        )
        .unwrap();
        assert_eq!(read.fidelity, Some(Kind::ClosedForm));
        assert_eq!((&read.items[0].kind, read.items[0].size), (&Kind::Exact, 3));
    }

    /// A list where the document has one value is read past as a member of the wrong type is
    /// (an outside check found `{"devices": [], "operations": 0}` told of `/devices` alone), but
    /// not as an item of a list, whose removal would renumber the items after it.
    #[test]
    fn a_list_in_a_members_place_is_read_past() {
        #[derive(Debug, serde::Deserialize, serde::Serialize)]
        #[serde(deny_unknown_fields)]
        #[allow(dead_code, reason = "only read")]
        struct Item {
            size: u32,
        }
        #[derive(Debug, serde::Deserialize, serde::Serialize)]
        #[serde(deny_unknown_fields)]
        #[allow(dead_code, reason = "only read")]
        struct Doc {
            name: Option<String>,
            count: Option<u64>,
            #[serde(default)]
            items: Vec<Item>,
        }
        let named = |text: &str| -> Vec<String> {
            match from_json::<Doc>(text, &["/items"]) {
                Ok(_) => Vec::new(),
                Err(invalid) => invalid.errors().iter().map(|e| e.to_string()).collect(),
            }
        };
        let list = LIST_IN_A_MEMBERS_PLACE;
        assert_eq!(
            named(r#"{"name": [], "count": "x", "items": [{"size": [1]}]}"#),
            [
                format!("/items/0/size: {list}"),
                format!("/name: {list}"),
                r#"/count: invalid type: string "x", expected a whole number from 0 to 18446744073709551615"#
                    .to_owned(),
            ]
        );
        // An item of a list: listed, and the end of the list (`/name` is not read).
        assert_eq!(
            named(r#"{"count": [], "items": [[1]], "name": 5}"#),
            [format!("/count: {list}"), format!("/items/0: {list}")]
        );
        // A document of lists only where they belong reads as before.
        let read: Doc = from_json(r#"{"items": [{"size": 2}]}"#, &["/items"]).unwrap();
        assert_eq!(read.items.len(), 1);
    }

    /// Up to [`MAX_FAULTS`] members are read past in a small document, fewer in a large one, so
    /// that a hostile body costs a few readings at most ([`READ_PAST_BYTES`]).
    #[test]
    fn a_large_document_is_read_past_fewer_faults() {
        #[derive(Debug, serde::Deserialize, serde::Serialize)]
        #[serde(deny_unknown_fields)]
        #[allow(dead_code, reason = "only read")]
        struct Doc {
            #[serde(default)]
            list: Vec<u64>,
        }
        let unknown: Vec<String> = (0..30).map(|i| format!(r#""x{i}": 0"#)).collect();
        let document = |items: usize| {
            let list = vec!["1000000"; items].join(",");
            format!(r#"{{{}, "list": [{list}]}}"#, unknown.join(","))
        };
        // The members named, and whether a last entry says the reading stopped with more to read.
        let faults = |text: &str| match read_past_faults::<Doc>(text, &["/list"]) {
            Ok((_, faults)) => (faults.len(), false),
            Err(invalid) => {
                let errors = invalid.errors();
                let stopped = errors.last().is_some_and(|last| {
                    last.pointer.is_empty() && last.detail.starts_with("read past")
                });
                (errors.len() - usize::from(stopped), stopped)
            }
        };
        assert_eq!(faults(&document(10)), (MAX_FAULTS, true));
        // About 2 MB: read twice.
        let large = document(250_000);
        assert_eq!(READ_PAST_BYTES / large.len(), 2, "{}", large.len());
        assert_eq!(faults(&large), (2, true));
        // One fault fewer than the readings: all of it read, so no last entry.
        let fewer: Vec<String> = (1..MAX_FAULTS).map(|i| format!(r#""x{i}": 0"#)).collect();
        let whole = format!(r#"{{{}, "list": [1]}}"#, fewer.join(","));
        assert_eq!(faults(&whole), (MAX_FAULTS - 1, false));
    }

    #[test]
    fn bytes_that_are_not_utf8_name_the_value_they_fall_in() {
        let cases: [(&[u8], &str); 4] = [
            (b"{\"name\": \"ab\xff\"}", "/name"),
            (
                b"{\"scenario\": {\"circuit\": {\"\xc3\x28\": 1}}}",
                "/scenario/circuit",
            ),
            (b"{\"scatter\": [{}, {\"per\": \"\xfe", "/scatter/1/per"),
            (b"\xff{}", ""),
        ];
        for (bytes, pointer) in cases {
            let error = std::str::from_utf8(bytes).unwrap_err();
            let invalid = not_utf8(bytes, &error);
            assert!(invalid.is_syntax(), "{invalid}");
            assert_eq!(invalid.pointers(), [pointer], "{invalid}");
            assert!(
                invalid.to_string().contains("not UTF-8 at byte"),
                "{invalid}"
            );
        }
    }

    #[test]
    fn pointer_tokens_are_escaped() {
        assert_eq!(
            Pointer::root().child("a/b").child("m~n").child(3).as_str(),
            "/a~1b/m~0n/3"
        );
    }

    fn pointers(text: &str) -> Vec<String> {
        let err = from_json::<serde_json::Value>(text, &[]).unwrap_err();
        assert_eq!(err.kind(), InputErrorKind::Rule, "{err}");
        err.errors().iter().map(|e| e.pointer.clone()).collect()
    }

    #[test]
    fn a_number_beyond_f64_breaks_a_rule_at_its_field() {
        assert_eq!(pointers(r#"{"a": {"b": 1e400}}"#), ["/a/b"]);
        assert_eq!(pointers(r#"{"a": -1e400}"#), ["/a"]);
        // Written as not zero, read as 0: named too (serde_json rounds it to 0 without a word).
        assert_eq!(pointers(r#"{"a": {"b": [1, 1e-400]}}"#), ["/a/b/1"]);
        assert_eq!(
            pointers(r#"{"x\"y": 0.0, "s": "1e-400", "c/d": -2.5e-999}"#),
            ["/c~1d"]
        );
        let zeros = r#"{"a": 0e-999, "b": 0.000, "c": -0, "d": 5e-324, "e": {"1e-400": 1}}"#;
        assert!(from_json::<serde_json::Value>(zeros, &[]).is_ok());
    }

    #[test]
    fn a_member_given_twice_is_named() {
        assert_eq!(pointers(r#"{"a": {"b": 1, "b": 2}}"#), ["/a/b"]);
        assert_eq!(pointers(r#"{"a": 1, "c": {}, "a": 1}"#), ["/a"]);
    }

    #[test]
    fn text_longer_than_the_limit_is_named_as_a_value_or_a_member() {
        let long = "x".repeat(MAX_TEXT_CHARS + 1);
        assert_eq!(
            pointers(&format!(r#"{{"a": {{"b": "{long}"}}}}"#)),
            ["/a/b"]
        );
        assert_eq!(
            pointers(&format!(r#"{{"a": {{"{long}": 1}}}}"#)),
            [format!("/a/{long}")]
        );
        let longest = "é".repeat(MAX_TEXT_CHARS);
        assert!(from_json::<serde_json::Value>(&format!(r#"{{"a": "{longest}"}}"#), &[]).is_ok());
    }

    #[test]
    fn text_holding_nul_is_named_as_a_value_or_a_member() {
        let refused = |text: &str| {
            from_json::<serde_json::Value>(text, &[])
                .unwrap_err()
                .errors
        };
        let value = refused(r#"{"name": "a\u0000b"}"#);
        assert_eq!(value[0].pointer, "/name");
        assert_eq!(value[0].detail, format!("text {NO_NUL}"));
        let member = refused(r#"{"a": {"\u0000": 1}}"#);
        assert_eq!(member[0].pointer, "/a/\u{0}");
        assert_eq!(member[0].detail, format!("a member's name {NO_NUL}"));
        // Other control characters are text like any other.
        assert!(from_json::<serde_json::Value>(r#"{"name": "a\u0001\n"}"#, &[]).is_ok());
    }

    #[test]
    fn an_integral_number_fills_an_integer_field_and_a_fraction_does_not() {
        assert_eq!(from_json::<u64>("2.0", &[]), Ok(2));
        assert_eq!(from_json::<u64>("1e3", &[]), Ok(1000));
        assert_eq!(from_json::<i64>("-4.0", &[]), Ok(-4));
        assert!(from_json::<u64>("2.5", &[]).is_err());
        assert!(from_json::<u64>("1.8446744073709552e19", &[]).is_err());
        // Above 2^53 an f64 is not the integer written: a seed of 12345678901234567.5 ran as
        // 12345678901234568, one of 9007199254740993.0 as ...992. Digits alone are exact.
        assert_eq!(
            from_json::<u64>("9007199254740991.0", &[]),
            Ok((1 << 53) - 1)
        );
        assert_eq!(
            from_json::<i64>("-9007199254740991.0", &[]),
            Ok(1 - (1 << 53))
        );
        for written in [
            "12345678901234567.5",
            "9007199254740993.0",
            "9.007199254740992e15",
        ] {
            assert!(from_json::<u64>(written, &[]).is_err(), "{written}");
        }
        assert_eq!(
            from_json::<u64>("9007199254740993", &[]),
            Ok(9_007_199_254_740_993)
        );
    }

    #[test]
    fn a_number_in_a_message_is_short() {
        let cases = [
            (1e308, "1e308"),
            (-1e308, "-1e308"),
            (1e16, "1e16"),
            (123456.5, "123456.5"),
            (-1.0, "-1"),
            (0.0, "0"),
            (0.00025, "0.00025"),
            (1e-7, "1e-7"),
            (f64::NAN, "NaN"),
        ];
        for (x, text) in cases {
            assert_eq!(shown(x), text);
        }
    }

    #[test]
    fn trailing_garbage_is_malformed() {
        let err = from_json::<serde_json::Value>("{} x", &[]).unwrap_err();
        assert!(err.is_syntax(), "{err}");
    }

    /// A number JSON does not have, given for a field, names the field (a sweep of the HTTP API
    /// found only a line and a column); text that is not JSON from the start names the document.
    #[test]
    fn text_that_stops_being_json_inside_a_field_names_the_field() {
        let field = "/scatter/0/distribution/max";
        // `0x10` is the number 0, then text where a `,` or `}` of its object should be.
        let its_object = "/scatter/0/distribution";
        for (literal, at) in [
            ("NaN", field),
            ("Infinity", field),
            ("-Infinity", field),
            ("+1", field),
            ("01", field),
            (".5", field),
            ("0x10", its_object),
        ] {
            let text = format!(r#"{{"scatter": [{{"distribution": {{"max": {literal}}}}}]}}"#);
            let err = from_json::<serde_json::Value>(&text, &["/scatter"]).unwrap_err();
            assert!(err.is_syntax(), "{literal}: {err}");
            assert_eq!(err.pointers(), [at], "{literal}: {err}");
            assert!(
                err.errors()[0].detail.starts_with("malformed JSON: "),
                "{err}"
            );
        }
        for text in ["not JSON", "", "{} x"] {
            let err = from_json::<serde_json::Value>(text, &[]).unwrap_err();
            assert_eq!(
                (err.is_syntax(), err.pointers()),
                (true, vec![""]),
                "{text:?}: {err}"
            );
        }
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
