//! What a succeeded job produced never changes, so its representations carry an `ETag` and may be
//! cached for a year without asking again; `If-None-Match` with a current tag gets 304 and no body.

use super::AppState;
use axum::body::{Body, Bytes};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use sha2::{Digest, Sha256};

/// The OpenAPI response of a request whose `If-None-Match` names the current tag.
#[derive(utoipa::IntoResponses)]
#[response(
    status = 304,
    description = "Not modified: If-None-Match names the current ETag"
)]
pub struct NotModified;

/// Declares the `If-None-Match` an operation that may answer [`NotModified`] reads.
pub fn declare_if_none_match(operation: &mut utoipa::openapi::path::Operation) {
    use utoipa::openapi::path::{ParameterBuilder, ParameterIn};
    use utoipa::openapi::{ObjectBuilder, Required, Type};
    let parameter = ParameterBuilder::new()
        .name("If-None-Match")
        .parameter_in(ParameterIn::Header)
        .required(Required::False)
        .description(Some(
            "ETags of a copy the client holds (or `*`): 304 and no body when one is the \
             current tag (weak comparison)",
        ))
        .schema(Some(ObjectBuilder::new().schema_type(Type::String)))
        .example(Some(serde_json::json!(
            "W/\"3f2a9c0d5e7b14f68a2c9e0b7d4f1a36\""
        )))
        .build();
    operation
        .parameters
        .get_or_insert_with(Vec::new)
        .push(utoipa::openapi::RefOr::T(parameter));
}

/// A succeeded job's result, distribution or life, as `content_type`, with its validator.
pub fn immutable(
    state: &AppState,
    request: &HeaderMap,
    content_type: &'static str,
    body: impl Into<Bytes>,
) -> Response {
    immutable_tagged(state, request, content_type, Tagged::new(body))
}

/// A representation's bytes with their tag, which can be made apart from the response (a large
/// one on the blocking pool).
pub struct Tagged {
    tag: HeaderValue,
    body: Bytes,
}

impl Tagged {
    pub fn new(body: impl Into<Bytes>) -> Self {
        let body = body.into();
        Self {
            tag: entity_tag(&body),
            body,
        }
    }
}

/// As [`immutable`], for bytes already tagged.
pub fn immutable_tagged(
    state: &AppState,
    request: &HeaderMap,
    content_type: &'static str,
    tagged: Tagged,
) -> Response {
    immutable_body(
        state,
        request,
        content_type,
        tagged.tag,
        Body::from(tagged.body),
    )
}

/// As [`immutable`], with a tag from `identity`, bytes that name the content once and for all
/// (the job and what of it), not from the body: a stream cannot be hashed before it is sent, and
/// hashing a large stored Result took an async thread several milliseconds per request.
pub fn immutable_identified(
    state: &AppState,
    request: &HeaderMap,
    content_type: &'static str,
    identity: &[u8],
    body: Body,
) -> Response {
    immutable_body(state, request, content_type, entity_tag(identity), body)
}

/// The 304 of [`immutable_identified`], before anything is read, when the request's
/// `If-None-Match` already names `identity`'s tag.
pub fn not_modified(state: &AppState, request: &HeaderMap, identity: &[u8]) -> Option<Response> {
    let tag = entity_tag(identity);
    matches_any(request, &tag).then(|| unchanged(validators(state, tag)))
}

/// A 304 with `validators`, and the `Vary` its 200 would carry (RFC 9110 section 15.4.5): the
/// compression layer adds `accept-encoding` to a 200 only, and the route's `accept` is set by its
/// own layer on both.
fn unchanged<const N: usize>(validators: [(header::HeaderName, HeaderValue); N]) -> Response {
    let mut response = (StatusCode::NOT_MODIFIED, validators).into_response();
    response
        .headers_mut()
        .append(header::VARY, HeaderValue::from_static("accept-encoding"));
    response
}

fn immutable_body(
    state: &AppState,
    request: &HeaderMap,
    content_type: &'static str,
    tag: HeaderValue,
    body: Body,
) -> Response {
    let unchanged = matches_any(request, &tag);
    let headers = validators(state, tag);
    if unchanged {
        return self::unchanged(headers);
    }
    let content_type = [(header::CONTENT_TYPE, HeaderValue::from_static(content_type))];
    (headers, content_type, body).into_response()
}

/// What a 200 and a 304 of an immutable representation carry: its tag and how long it may be
/// kept, and by whom.
fn validators(state: &AppState, tag: HeaderValue) -> [(header::HeaderName, HeaderValue); 3] {
    // With API keys a result is its owner's alone: no shared cache may keep it for others, and a
    // browser whose key changed asks again rather than show the last key's copy (the dashboard's
    // key field; found from outside: the other key got 200 from the browser's cache).
    let (cache_control, vary) = if state.key_owners.is_empty() {
        ("public, max-age=31536000, immutable", "accept")
    } else {
        (
            "private, max-age=31536000, immutable",
            "accept, authorization",
        )
    };
    [
        (header::ETAG, tag),
        (
            header::CACHE_CONTROL,
            HeaderValue::from_static(cache_control),
        ),
        // JSON or CSV, as `format` or else `Accept` asks (`jobs::Format::negotiate`).
        (header::VARY, HeaderValue::from_static(vary)),
    ]
}

/// One of the server's own files (a dashboard page, its script or style), with its tag made
/// once: asked again at every use (`no-cache`), answered 304 while the build that serves it is
/// the one that served it before, so a reload moves a few hundred bytes rather than the whole
/// script, and a new build is seen at once.
pub struct OwnFile {
    content_type: &'static str,
    body: &'static str,
    tag: HeaderValue,
}

impl OwnFile {
    pub fn new(content_type: &'static str, body: &'static str) -> Self {
        let tag = entity_tag(body.as_bytes());
        Self {
            content_type,
            body,
            tag,
        }
    }

    /// The file, or 304 where `If-None-Match` names its tag.
    pub fn respond(&self, request: &HeaderMap) -> Response {
        let headers = [
            (header::ETAG, self.tag.clone()),
            (header::CACHE_CONTROL, HeaderValue::from_static("no-cache")),
        ];
        if matches_any(request, &self.tag) {
            return unchanged(headers);
        }
        let content_type = [(
            header::CONTENT_TYPE,
            HeaderValue::from_static(self.content_type),
        )];
        (headers, content_type, self.body).into_response()
    }
}

/// A weak tag from the SHA-256 of the bytes: weak because compression may send other bytes for
/// the same content, which a strong tag would have to tell apart.
fn entity_tag(body: &[u8]) -> HeaderValue {
    let hex: String = Sha256::digest(body)[..16]
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    HeaderValue::from_str(&format!("W/\"{hex}\"")).expect("hex is a valid header value")
}

/// Whether `If-None-Match` names `tag` (weak comparison, RFC 9110 section 13.1.2) or is `*`.
fn matches_any(request: &HeaderMap, tag: &HeaderValue) -> bool {
    let opaque = |t: &str| t.trim().trim_start_matches("W/").to_owned();
    let ours = opaque(tag.to_str().unwrap_or_default());
    request
        .get_all(header::IF_NONE_MATCH)
        .iter()
        .filter_map(|value| value.to_str().ok())
        .flat_map(|value| value.split(','))
        .any(|candidate| candidate.trim() == "*" || opaque(candidate) == ours)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn asking(if_none_match: &str) -> HeaderMap {
        let mut headers = HeaderMap::new();
        headers.insert(
            header::IF_NONE_MATCH,
            HeaderValue::from_str(if_none_match).unwrap(),
        );
        headers
    }

    #[test]
    fn if_none_match_compares_tags_weakly_in_a_list_or_as_a_star() {
        let tag = entity_tag(b"{}");
        let opaque = tag.to_str().unwrap().trim_start_matches("W/").to_owned();
        assert!(matches_any(&asking(tag.to_str().unwrap()), &tag));
        assert!(
            matches_any(&asking(&opaque), &tag),
            "a strong form matches weakly"
        );
        assert!(matches_any(&asking(&format!("\"other\", {opaque}")), &tag));
        assert!(matches_any(&asking("*"), &tag));
        assert!(!matches_any(&asking("\"other\""), &tag));
        assert!(!matches_any(&HeaderMap::new(), &tag));
    }

    #[test]
    fn other_bytes_get_another_tag() {
        assert_ne!(entity_tag(b"{\"a\":1}"), entity_tag(b"{\"a\":2}"));
    }
}
