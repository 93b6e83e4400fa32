//! Every error a client can see, as `application/problem+json` (RFC 9457), in one place.
//! Internal errors are logged with their cause and reach the client as a bare 500.

use crate::domain::QueueBound;
use crate::store::StoreError;
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use bouncewear_model::{FieldError, InvalidInput};
use serde::Serialize;
use std::time::Duration;
use utoipa::ToSchema;

/// The media type of every error response.
pub const PROBLEM: &str = "application/problem+json";

/// An RFC 9457 problem document.
#[derive(Debug, Serialize, ToSchema)]
pub struct Problem {
    /// Always `about:blank`: the status says what kind of problem it is.
    #[serde(rename = "type")]
    pub kind: &'static str,
    /// The status' reason phrase.
    pub title: String,
    /// The HTTP status code.
    pub status: u16,
    /// What went wrong, in words.
    pub detail: String,
    /// For invalid input: each field at fault, as a JSON pointer into the request body.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub errors: Vec<ProblemField>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct ProblemField {
    /// JSON pointer to the field in the request body (`""` is the whole document).
    pub pointer: String,
    /// The rule it broke, with the value.
    pub detail: String,
}

#[derive(Debug, thiserror::Error)]
pub enum ApiError {
    #[error(
        "Idempotency-Key `{0}` was used with another body within 24 hours; send a new key for a new request"
    )]
    KeyReused(String),
    #[error("the request body is not valid JSON")]
    MalformedJson(InvalidInput),
    #[error("the request body breaks the contract")]
    Invalid(InvalidInput),
    #[error("{0}")]
    BadRequest(String),
    #[error("a valid API key is required (Authorization: Bearer KEY)")]
    Unauthorized,
    #[error("{0}")]
    NotFound(String),
    #[error("{0}")]
    Conflict(String),
    #[error("the request body is larger than {0} bytes")]
    TooLarge(usize),
    #[error(
        "the request body must be application/json in UTF-8 (no charset, or charset=utf-8), in one \
         Content-Type header"
    )]
    UnsupportedMediaType,
    #[error("a request body is read as it is sent: send it without `Content-Encoding: {0}`")]
    UnsupportedEncoding(String),
    #[error(
        "the queue, or this API key's share of it, is full: at most {} in all and {} per API \
         key; retry later",
        unfinished_jobs(.0.total),
        unfinished_jobs(.0.per_owner)
    )]
    QueueFull(QueueBound),
    /// The key's jobs store its quota or more ([`StoreError::OverQuota`]).
    #[error("{0}")]
    OverQuota(String),
    /// A request a browser sends on another site's behalf to a server without keys (see
    /// docs/contract.md, "API keys").
    #[error("{0}")]
    CrossSite(String),
    #[error(
        "this API key (every client, where the server has no keys) holds {0} event streams already, the most it may; close one, or retry later"
    )]
    TooManyStreams(usize),
    /// Every slot of a schedule's manual runs within one instant is taken.
    #[error("too many manual runs of this schedule at once; retry later")]
    TooManyRuns,
    #[error("method not allowed")]
    MethodNotAllowed,
    #[error("the request body did not arrive within {} s", .0.as_secs_f64())]
    BodyTimeout(Duration),
    #[error("no answer within {} s; retry later", .0.as_secs_f64())]
    Timeout(Duration),
    /// Large responses held for clients still reading them fill `--max-response-mb`.
    #[error(
        "large responses that clients have not yet read fill the {0} MB this server holds \
         (--max-response-mb); retry later"
    )]
    ResponsesHeld(u64),
    /// The storage failed for now: logged, and the client told to retry.
    #[error("the database is unavailable; retry later")]
    Unavailable(Internal),
    /// Readiness failed; the detail is for operators and names no secret.
    #[error("{0}")]
    NotReady(String),
    #[error("internal error")]
    Internal(#[from] Internal),
}

/// A query string that does not read as the route's parameters: 400 naming the parameter, in
/// words a query's writer knows (Rust's parsers say "invalid digit found in string").
impl From<axum::extract::rejection::QueryRejection> for ApiError {
    fn from(rejection: axum::extract::rejection::QueryRejection) -> Self {
        const WORDS: [(&str, &str); 6] = [
            ("invalid digit found in string", "expected a whole number"),
            (
                "number too large to fit in target type",
                "a whole number too large",
            ),
            (
                "cannot parse integer from empty string",
                "expected a whole number, got nothing",
            ),
            (
                "cannot parse float from empty string",
                "expected a number, got nothing",
            ),
            ("invalid float literal", "expected a number"),
            (
                "provided string was not `true` or `false`",
                "expected true or false",
            ),
        ];
        let text = rejection.body_text();
        let mut plain = text
            .strip_prefix("Failed to deserialize query string: ")
            .unwrap_or(&text)
            .to_owned();
        for (rust, words) in WORDS {
            plain = plain.replace(rust, words);
        }
        ApiError::BadRequest(format!("the query string: {plain}"))
    }
}

/// A cause that must not reach the client: logged, then reported as a bare 500.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct Internal(pub String);

/// The store's outcomes in HTTP's terms, in this one place: what the client asked for does not
/// exist (404) or contradicts the stored state (409); a database that cannot answer now is 503
/// with Retry-After (logged); anything else is ours (500, logged).
impl From<StoreError> for ApiError {
    fn from(error: StoreError) -> Self {
        match error {
            StoreError::NotFound { .. } => ApiError::NotFound(error.to_string()),
            StoreError::Conflict(detail) => ApiError::Conflict(detail),
            StoreError::NotReady(detail) | StoreError::NoRoom(detail) => ApiError::NotReady(detail),
            StoreError::OverQuota { .. } | StoreError::TooManySchedules { .. } => {
                ApiError::OverQuota(error.to_string())
            }
            other if other.is_out_of_space() => {
                tracing::warn!(error = %other, "the database's disk is full");
                ApiError::NotReady(
                    "the database has no room on its disk; retry once space is freed".to_owned(),
                )
            }
            other if other.is_read_only() => {
                tracing::warn!(error = %other, "the database takes no writes");
                ApiError::NotReady(
                    "the database takes no writes: it is read-only (the file's or its directory's \
                     permissions, a read-only mount, or a PostgreSQL standby); retry once it does"
                        .to_owned(),
                )
            }
            other if other.is_unavailable() => ApiError::Unavailable(Internal(other.to_string())),
            other => ApiError::Internal(Internal(other.to_string())),
        }
    }
}

impl From<crate::plots::PlotError> for ApiError {
    fn from(error: crate::plots::PlotError) -> Self {
        ApiError::NotFound(error.to_string())
    }
}

impl From<InvalidInput> for ApiError {
    fn from(invalid: InvalidInput) -> Self {
        if invalid.is_syntax() {
            ApiError::MalformedJson(invalid)
        } else {
            ApiError::Invalid(invalid)
        }
    }
}

impl ApiError {
    pub fn status(&self) -> StatusCode {
        match self {
            ApiError::MalformedJson(_) | ApiError::BadRequest(_) => StatusCode::BAD_REQUEST,
            ApiError::Invalid(_) | ApiError::KeyReused(_) => StatusCode::UNPROCESSABLE_ENTITY,
            ApiError::Unauthorized => StatusCode::UNAUTHORIZED,
            ApiError::OverQuota(_) | ApiError::CrossSite(_) => StatusCode::FORBIDDEN,
            ApiError::NotFound(_) => StatusCode::NOT_FOUND,
            ApiError::Conflict(_) => StatusCode::CONFLICT,
            ApiError::TooLarge(_) => StatusCode::PAYLOAD_TOO_LARGE,
            ApiError::UnsupportedMediaType | ApiError::UnsupportedEncoding(_) => {
                StatusCode::UNSUPPORTED_MEDIA_TYPE
            }
            ApiError::QueueFull(_) | ApiError::TooManyStreams(_) | ApiError::TooManyRuns => {
                StatusCode::TOO_MANY_REQUESTS
            }
            ApiError::MethodNotAllowed => StatusCode::METHOD_NOT_ALLOWED,
            ApiError::BodyTimeout(_) => StatusCode::REQUEST_TIMEOUT,
            ApiError::Timeout(_)
            | ApiError::Unavailable(_)
            | ApiError::NotReady(_)
            | ApiError::ResponsesHeld(_) => StatusCode::SERVICE_UNAVAILABLE,
            ApiError::Internal(_) => StatusCode::INTERNAL_SERVER_ERROR,
        }
    }

    fn fields(&self) -> Vec<ProblemField> {
        let to_fields = |errors: &[FieldError]| {
            errors
                .iter()
                .map(|e| ProblemField {
                    pointer: e.pointer.clone(),
                    detail: e.detail.clone(),
                })
                .collect()
        };
        match self {
            ApiError::MalformedJson(invalid) | ApiError::Invalid(invalid) => {
                to_fields(invalid.errors())
            }
            _ => Vec::new(),
        }
    }

    fn detail(&self) -> String {
        match self {
            ApiError::MalformedJson(invalid) | ApiError::Invalid(invalid) => invalid.to_string(),
            other => other.to_string(),
        }
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let status = self.status();
        match &self {
            ApiError::Internal(cause) => tracing::error!(%cause, "internal error"),
            ApiError::Unavailable(cause) => tracing::error!(%cause, "the database is unavailable"),
            ApiError::NotReady(reason) => tracing::warn!(%reason, "not ready"),
            _ => {}
        }
        let problem = Problem {
            kind: "about:blank",
            title: status.canonical_reason().unwrap_or("Error").to_owned(),
            status: status.as_u16(),
            detail: self.detail(),
            errors: self.fields(),
        };
        let mut response = (status, axum::Json(problem)).into_response();
        let headers = response.headers_mut();
        headers.insert(
            header::CONTENT_TYPE,
            HeaderValue::from_static("application/problem+json"),
        );
        match self {
            ApiError::QueueFull(_)
            | ApiError::TooManyStreams(_)
            | ApiError::TooManyRuns
            | ApiError::Unavailable(_)
            | ApiError::NotReady(_)
            | ApiError::ResponsesHeld(_) => {
                headers.insert(header::RETRY_AFTER, HeaderValue::from_static("5"));
            }
            // The connection may still hold the rest of a body nobody reads: start afresh.
            ApiError::Timeout(_) => {
                headers.insert(header::RETRY_AFTER, HeaderValue::from_static("5"));
                headers.insert(header::CONNECTION, HeaderValue::from_static("close"));
            }
            ApiError::BodyTimeout(_) => {
                headers.insert(header::CONNECTION, HeaderValue::from_static("close"));
            }
            ApiError::Unauthorized => {
                headers.insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
            }
            _ => {}
        }
        response
    }
}

/// The problems most endpoints share, for their OpenAPI `responses(...)`: each written once.
pub mod responses {
    use super::Problem;
    use utoipa::IntoResponses;

    /// Every `/v1` call on a server with API keys.
    #[derive(IntoResponses)]
    #[response(
        status = 401,
        description = "Missing or unknown API key",
        content_type = "application/problem+json"
    )]
    pub struct Unauthorized(pub Problem);

    /// A request body that is not a valid document.
    #[derive(IntoResponses)]
    pub enum BodyRejected {
        #[response(
            status = 400,
            description = "Malformed JSON",
            content_type = "application/problem+json"
        )]
        Malformed(Problem),
        #[response(
            status = 413,
            description = "Body too large",
            content_type = "application/problem+json"
        )]
        TooLarge(Problem),
        #[response(
            status = 415,
            description = "Body is not `application/json` in UTF-8 (another type, or a charset other than utf-8), or comes with a `Content-Encoding`",
            content_type = "application/problem+json"
        )]
        NotJson(Problem),
        #[response(
            status = 422,
            description = "A field breaks a rule; `errors` names each by JSON pointer",
            content_type = "application/problem+json"
        )]
        Invalid(Problem),
    }

    #[derive(IntoResponses)]
    #[response(
        status = 400,
        description = "Bad query",
        content_type = "application/problem+json"
    )]
    pub struct BadQuery(pub Problem);

    #[derive(IntoResponses)]
    #[response(
        status = 404,
        description = "No such job (for this key)",
        content_type = "application/problem+json"
    )]
    pub struct NoSuchJob(pub Problem);

    #[derive(IntoResponses)]
    #[response(
        status = 404,
        description = "No such schedule (for this key)",
        content_type = "application/problem+json"
    )]
    pub struct NoSuchSchedule(pub Problem);

    /// A schedule stored before a rule its template now breaks: it runs no more until PUT anew.
    #[derive(IntoResponses)]
    #[response(
        status = 409,
        description = "The schedule's stored template no longer validates; PUT the schedule with a valid one",
        content_type = "application/problem+json"
    )]
    pub struct StaleTemplate(pub Problem);

    /// A schedule's runs, or other PUTs, moved it on at every try of a PUT.
    #[derive(IntoResponses)]
    #[response(
        status = 409,
        description = "The schedule kept changing while it was replaced (its runs, or other PUTs); send the PUT again",
        content_type = "application/problem+json"
    )]
    pub struct ReplacedMeanwhile(pub Problem);

    /// Results exist once a job succeeded.
    #[derive(IntoResponses)]
    #[response(
        status = 409,
        description = "Not succeeded (yet)",
        content_type = "application/problem+json"
    )]
    pub struct NotSucceeded(pub Problem);

    /// Every request: the server answers within `--request-timeout-seconds`, and its database
    /// may fail for a while.
    #[derive(IntoResponses)]
    #[response(
        status = 503,
        description = "No answer within the request timeout, or the database is unavailable; retry after Retry-After seconds",
        content_type = "application/problem+json",
        headers(("Retry-After" = u32, description = "Seconds to wait before retrying"))
    )]
    pub struct Unavailable(pub Problem);

    /// Every request with a body: it must arrive whole within `--body-timeout-seconds`.
    #[derive(IntoResponses)]
    #[response(
        status = 408,
        description = "The body did not arrive within the body timeout",
        content_type = "application/problem+json"
    )]
    pub struct BodyTimeout(pub Problem);

    #[derive(IntoResponses)]
    #[response(
        status = 429,
        description = "The queue is full; retry after Retry-After seconds",
        content_type = "application/problem+json",
        headers(("Retry-After" = u32, description = "Seconds to wait before retrying"))
    )]
    pub struct QueueFull(pub Problem);

    /// A new job of a key whose jobs store `--max-stored-mb-per-key` or more.
    #[derive(IntoResponses)]
    #[response(
        status = 403,
        description = "The jobs of this API key (of every client, where the server has no keys) store its quota (`--max-stored-mb-per-key`) or more; delete some first",
        content_type = "application/problem+json"
    )]
    pub struct OverQuota(pub Problem);

    /// A new schedule of a key that holds `--max-schedules-per-key` schedules.
    #[derive(IntoResponses)]
    #[response(
        status = 403,
        description = "This API key (every client, where the server has no keys) holds the most schedules it may (`--max-schedules-per-key`, default 100); delete one first",
        content_type = "application/problem+json"
    )]
    pub struct TooManySchedules(pub Problem);

    /// Every request to a server without API keys that names a host other than loopback, and
    /// every change whose `Origin` is another site (`limits`: DNS rebinding, cross-site forms).
    #[derive(IntoResponses)]
    #[response(
        status = 403,
        description = "Without API keys: a `Host` field or an absolute target that names no loopback host, or a change (not GET, HEAD or OPTIONS) whose `Origin` is not on one",
        content_type = "application/problem+json"
    )]
    pub struct ForeignName(pub Problem);

    /// Event streams: each API key holds at most `--max-streams-per-key` at once.
    #[derive(IntoResponses)]
    #[response(
        status = 429,
        description = "This key holds the most event streams it may; retry after Retry-After seconds",
        content_type = "application/problem+json",
        headers(("Retry-After" = u32, description = "Seconds to wait before retrying"))
    )]
    pub struct TooManyStreams(pub Problem);
}

/// `n` unfinished job(s), in words.
fn unfinished_jobs(n: u64) -> String {
    match n {
        1 => "1 unfinished job".to_owned(),
        n => format!("{n} unfinished jobs"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_database_that_cannot_answer_is_503_with_retry_after_and_no_cause() {
        let response =
            ApiError::from(StoreError::Database(sqlx::Error::PoolTimedOut)).into_response();
        assert_eq!(response.status(), StatusCode::SERVICE_UNAVAILABLE);
        assert_eq!(response.headers()[header::RETRY_AFTER], "5");
        assert_eq!(response.headers()[header::CONTENT_TYPE], PROBLEM);
    }

    #[test]
    fn stored_data_that_does_not_decode_is_still_ours() {
        let error = StoreError::Database(sqlx::Error::ColumnNotFound("seq".to_owned()));
        let response = ApiError::from(error).into_response();
        assert_eq!(response.status(), StatusCode::INTERNAL_SERVER_ERROR);
    }
}
