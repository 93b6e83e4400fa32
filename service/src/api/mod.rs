//! The HTTP API of docs/contract.md, one module per resource. Routes and their OpenAPI description
//! come from the same `#[utoipa::path]` handlers, so they cannot drift apart. Handlers speak HTTP
//! only: the rules are the domain's, the storage the store's.

pub mod cache;
pub mod calibrations;
pub mod compare;
pub mod error;
pub mod events;
pub mod held;
pub mod jobs;
pub mod known_query;
pub mod limits;
pub mod openapi;
pub mod plots;
pub mod schedules;
pub mod simulate;
pub mod system;
pub mod watch;

use crate::config::ServeConfig;
use crate::domain::{IdempotencyKey, Owner};
use crate::store::Store;
use crate::telemetry;
use axum::body::Bytes;
use axum::extract::{DefaultBodyLimit, FromRequest, FromRequestParts, Request, State};
use axum::http::header;
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use error::ApiError;
use metrics_exporter_prometheus::PrometheusHandle;
use std::collections::HashSet;
use std::sync::Arc;
use tokio::sync::Notify;
use tower_http::catch_panic::CatchPanicLayer;
use tower_http::compression::CompressionLayer;
use tower_http::request_id::{MakeRequestUuid, PropagateRequestIdLayer, SetRequestIdLayer};
use tower_http::set_header::SetResponseHeaderLayer;
use tower_http::trace::TraceLayer;
use utoipa::openapi::security::{HttpAuthScheme, HttpBuilder, SecurityScheme};
use utoipa::{Modify, OpenApi};
use utoipa_axum::router::OpenApiRouter;

#[derive(Clone)]
pub struct AppState {
    pub store: Arc<Store>,
    pub config: Arc<ServeConfig>,
    /// The owner (the SHA-256) of every accepted API key: keys themselves are never kept.
    pub key_owners: Arc<HashSet<Owner>>,
    /// Wakes an idle worker when a job is submitted.
    pub wake: Arc<Notify>,
    pub metrics: PrometheusHandle,
    /// Turns true at shutdown: event streams end so the server can drain.
    pub shutdown: tokio::sync::watch::Receiver<bool>,
    /// The one watcher of the queue behind every event stream.
    pub watch: Arc<watch::JobWatch>,
    /// Places for calibration fits ([`calibrations::places_for_fits`]).
    pub fits: Arc<tokio::sync::Semaphore>,
    /// Places for requests that parse whole Results (life, rare event, plots, comparisons,
    /// trends) or run a device (a rare event's check at submission), one per core: a Result of
    /// 1000 bins parses to hundreds of MB, and 256 comparisons at once took 6.5 GB; more wait
    /// their turn within the request timeout.
    pub parsing: Arc<tokio::sync::Semaphore>,
}

#[derive(OpenApi)]
#[openapi(
    info(title = "bouncewear", description = "Monte Carlo wear simulation of bouncing electrical contacts (McBride & Sharkh 1992). The contract is docs/contract.md; the physics docs/model.md."),
    modifiers(&BearerAuth),
    tags((name = "jobs", description = "Monte Carlo endurance jobs on a durable queue"), (name = "schedules", description = "Nightly runs of a job template and their trend"), (name = "simulate", description = "One make operation"), (name = "calibrations", description = "A scenario fitted to measured operations"), (name = "system", description = "Health, metrics, documentation"))
)]
struct ApiDoc;

struct BearerAuth;

impl Modify for BearerAuth {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        let components = openapi.components.get_or_insert_with(Default::default);
        components.add_security_scheme(
            "api_key",
            SecurityScheme::Http(
                HttpBuilder::new()
                    .scheme(HttpAuthScheme::Bearer)
                    .description(Some("Required when the server has API keys"))
                    .build(),
            ),
        );
    }
}

/// Every route in one router: the API with its OpenAPI document (built from the same handlers),
/// the docs UI, the dashboard, the fallbacks, and the layers every request passes.
pub fn router(state: AppState) -> axum::Router {
    let max_body = state.config.max_body_bytes;
    let admission = limits::Admission::new(&state);
    let held = held::Held::new(state.config.max_response_mb);
    let (keys, keys_too) = (Arc::clone(&state.key_owners), Arc::clone(&state.key_owners));
    let keyless = state.key_owners.is_empty();
    api_routes(state)
        .route("/", get(system::dashboard))
        .route("/jobs/{id}", get(system::job_page))
        .route("/dashboard/app.js", get(system::dashboard_script))
        .route("/dashboard/style.css", get(system::dashboard_style))
        .fallback(move |request: Request| async move {
            unmatched(
                &keys,
                &request,
                ApiError::NotFound("no such resource".to_owned()),
            )
        })
        .method_not_allowed_fallback(move |request: Request| async move {
            unmatched(&keys_too, &request, ApiError::MethodNotAllowed)
        })
        .layer(axum::middleware::from_fn_with_state(held, held::hold))
        .layer(axum::middleware::from_fn_with_state(keyless, same_site))
        .layer(DefaultBodyLimit::max(max_body))
        .layer(axum::middleware::from_fn_with_state(
            admission,
            limits::admit,
        ))
        .layer(axum::middleware::from_fn(telemetry::record_request))
        .layer(CatchPanicLayer::custom(|_| {
            IntoResponse::into_response(ApiError::Internal(error::Internal(
                "a handler panicked".into(),
            )))
        }))
        // gzip or br as the client accepts; event streams, images and tiny bodies stay as they are.
        .layer(CompressionLayer::new())
        .layer(axum::middleware::map_request(identity_acceptable))
        // One line per request at info; server errors are logged where they arise, with their cause.
        .layer(
            TraceLayer::new_for_http()
                .make_span_with(telemetry::request_span)
                .on_response(telemetry::log_response)
                .on_failure(()),
        )
        .layer(PropagateRequestIdLayer::x_request_id())
        .layer(SetRequestIdLayer::x_request_id(MakeRequestUuid))
        .layer(axum::middleware::map_request(usable_request_id))
        // Every answer, pages and API alike: no content sniffed into another type, no page framed
        // by another site (a "Run now" clicked through a frame), no job id sent on as a referrer,
        // and nothing run or loaded but this server's own scripts, styles and data.
        .layer(SetResponseHeaderLayer::if_not_present(
            header::CONTENT_SECURITY_POLICY,
            header::HeaderValue::from_static(CONTENT_SECURITY_POLICY),
        ))
        .layer(SetResponseHeaderLayer::if_not_present(
            header::X_CONTENT_TYPE_OPTIONS,
            header::HeaderValue::from_static("nosniff"),
        ))
        .layer(SetResponseHeaderLayer::if_not_present(
            header::X_FRAME_OPTIONS,
            header::HeaderValue::from_static("DENY"),
        ))
        .layer(SetResponseHeaderLayer::if_not_present(
            header::REFERRER_POLICY,
            header::HeaderValue::from_static("no-referrer"),
        ))
}

/// What a page (or a plot opened alone) may run and load: this server's own scripts, and styles,
/// images, fonts and requests from it; no plugin, no `<base>`, forms posted here only, framed by
/// no one. Styles may be inline (the plots' attributes, RapiDoc's shadow DOM); scripts may not. A
/// defence in depth: the dashboard writes every user's text as text, and an outside probe ran no
/// script from any name, path, fragment or query; this keeps it so should a page ever slip.
const CONTENT_SECURITY_POLICY: &str = "default-src 'none'; script-src 'self'; \
    style-src 'self' 'unsafe-inline'; img-src 'self' data:; font-src 'self'; connect-src 'self'; \
    base-uri 'none'; form-action 'self'; frame-ancestors 'none'";

/// Refuses, before any handler runs, what a browser sends on another site's behalf to a server
/// without keys (found from outside): a name other than a loopback one (a web page that made its
/// own name point at 127.0.0.1, DNS rebinding, reads and changes everything such a server holds),
/// and a change (any method but GET, HEAD and OPTIONS) from a page whose `Origin` is not on this
/// machine's loopback (a form posting to `/v1/jobs/{id}/cancel`). A server with keys needs
/// neither: a key is no credential a browser attaches to another site's request, and a proxy in
/// front of it may name it as it likes (a proxy that rewrote `Host` had every change of the
/// dashboard refused, found from outside). A client that is no browser sends no `Origin`.
async fn same_site(State(keyless): State<bool>, request: Request, next: Next) -> Response {
    match keyless.then(|| cross_site(&request)).flatten() {
        Some(refusal) => ApiError::CrossSite(refusal).into_response(),
        None => next.run(request).await,
    }
}

fn cross_site(request: &Request) -> Option<String> {
    // Every name the request gives: each `Host` field (a second one named another host after
    // `localhost`, and the first was read) and the target's own, in absolute form (`GET
    // http://attacker.example/...` with `Host: localhost` was answered; found from outside). A
    // field that is no text is no name of this machine.
    let mut names = (request.headers().get_all(header::HOST).iter())
        .map(|host| host.to_str().unwrap_or("?"))
        .chain(request.uri().authority().map(|a| a.as_str()));
    if let Some(host) = names.find(|host| !loopback_name(host)) {
        return Some(format!(
            "a server without API keys answers to loopback names only (localhost, 127.0.0.1, [::1]), not `{host}`: another name pointing here is how a web page would reach it; configure --api-key to serve other names"
        ));
    }
    let changes = !matches!(
        *request.method(),
        axum::http::Method::GET | axum::http::Method::HEAD | axum::http::Method::OPTIONS
    );
    let origin = request
        .headers()
        .get(header::ORIGIN)?
        .to_str()
        .unwrap_or("?");
    let local = (origin.split_once("://")).is_some_and(|(_, authority)| loopback_name(authority));
    (changes && !local).then(|| {
        format!(
            "a page of another site (Origin `{origin}`) may not change anything on a server without API keys; configure --api-key to serve pages of other names"
        )
    })
}

/// Whether `host` (a `Host` field: a name or address, and a port of digits) names this machine's
/// loopback: `localhost` and its subdomains, `127.0.0.0/8` (in the shorthand `inet_aton` reads
/// too, `127.1`, which a client may send as typed), `[::1]`.
fn loopback_name(host: &str) -> bool {
    let (name, port) = match host.strip_prefix('[') {
        Some(bracketed) => match bracketed.split_once(']') {
            Some((name, rest)) => (
                name,
                rest.strip_prefix(':')
                    .or(Some(rest).filter(|r| r.is_empty())),
            ),
            None => return false,
        },
        None => match host.rsplit_once(':') {
            Some((name, port)) => (name, Some(port)),
            None => (host, Some("")),
        },
    };
    if !port.is_some_and(|port| port.bytes().all(|b| b.is_ascii_digit())) {
        return false;
    }
    let name = name.strip_suffix('.').unwrap_or(name).to_ascii_lowercase();
    name == "localhost"
        || name.ends_with(".localhost")
        || name
            .parse::<std::net::Ipv6Addr>()
            .is_ok_and(|ip| ip.is_loopback())
        || ipv4_shorthand(&name).is_some_and(|ip| ip >> 24 == 127)
}

/// An IPv4 address as `inet_aton` reads it: one to four parts, each decimal, octal (`0` first)
/// or hexadecimal (`0x`), the last filling the bytes the others leave.
fn ipv4_shorthand(name: &str) -> Option<u32> {
    let parts: Vec<u64> = (name.split('.'))
        .map(
            |part| match part.strip_prefix("0x").or_else(|| part.strip_prefix("0X")) {
                Some(hex) => u64::from_str_radix(hex, 16).ok(),
                None if part.len() > 1 && part.starts_with('0') => {
                    u64::from_str_radix(part, 8).ok()
                }
                None => part.parse().ok(),
            },
        )
        .collect::<Option<_>>()?;
    let (last, leading) = parts.split_last()?;
    if leading.len() > 3 || leading.iter().any(|&byte| byte > 255) {
        return None;
    }
    let rest_bits = 8 * (4 - leading.len() as u32);
    if rest_bits < 64 && *last >= 1 << rest_bits {
        return None;
    }
    let high = (leading.iter()).fold(0_u64, |address, &byte| address << 8 | byte);
    u32::try_from(high << rest_bits | last).ok()
}

/// The request without a client's `X-Request-Id` that is no id (more than 128 characters, or
/// any but visible ASCII, or given twice): one of ours replaces it. A 9,000-character one was
/// echoed and logged whole with every request.
async fn usable_request_id(mut request: Request) -> Request {
    let mut given = request.headers().get_all("x-request-id").iter();
    let usable = match (given.next(), given.next()) {
        (Some(id), None) => {
            id.len() <= 128 && id.as_bytes().iter().all(|b| (b'!'..=b'~').contains(b))
        }
        _ => false,
    };
    if !usable {
        request.headers_mut().remove("x-request-id");
    }
    request
}

/// The request with the entries of `Accept-Encoding` that refuse the uncompressed form
/// (`identity;q=0`, `*;q=0`) dropped. For a client that accepts no coding tower-http's
/// compression answers 406, after the handler ran: the job it created or deleted answered as a
/// failure, so that a retry would create it twice. RFC 9110 (12.5.3) lets a server send the
/// uncompressed form instead, which this makes it do; a coding the client accepts is still used.
async fn identity_acceptable(mut request: Request) -> Request {
    // Every line of the field, as tower-http reads them, as one list; most requests refuse
    // nothing and pass on untouched, nothing allocated.
    let items = || {
        let lines = request.headers().get_all(header::ACCEPT_ENCODING).iter();
        lines
            .filter_map(|line| line.to_str().ok())
            .flat_map(|line| line.split(','))
            .map(str::trim)
    };
    if !items().any(refuses_identity) {
        return request;
    }
    let kept: Vec<&str> = items()
        .filter(|item| !item.is_empty() && !refuses_identity(item))
        .collect();
    let kept = header::HeaderValue::from_str(&kept.join(", ")).ok();
    let headers = request.headers_mut();
    headers.remove(header::ACCEPT_ENCODING);
    if let Some(kept) = kept.filter(|kept| !kept.is_empty()) {
        headers.insert(header::ACCEPT_ENCODING, kept);
    }
    request
}

/// Whether one item of `Accept-Encoding` refuses the uncompressed form: `identity` or `*` with
/// a weight of 0.
fn refuses_identity(item: &str) -> bool {
    let mut parts = item.split(';').map(str::trim);
    let coding = parts.next().unwrap_or_default();
    (coding.eq_ignore_ascii_case("identity") || coding == "*")
        && parts.any(|parameter| {
            parameter.split_once('=').is_some_and(|(name, weight)| {
                name.trim().eq_ignore_ascii_case("q")
                    && weight.trim().parse::<f64>().is_ok_and(|q| q == 0.0)
            })
        })
}

/// The documented routes, and the OpenAPI document built from the same handlers with its page.
fn api_routes(state: AppState) -> axum::Router {
    let v1 = OpenApiRouter::new()
        .merge(jobs::router())
        .merge(events::router())
        .merge(schedules::router())
        .merge(plots::router())
        .merge(compare::router())
        .merge(simulate::router())
        .merge(calibrations::router())
        .layer(axum::middleware::from_fn_with_state(
            state.clone(),
            authenticate,
        ));
    let (router, mut openapi) = OpenApiRouter::with_openapi(ApiDoc::openapi())
        .merge(v1)
        .merge(system::router())
        .split_for_parts();
    EveryRequest.modify(&mut openapi);
    let known = known_query::KnownQueries::of(&openapi);
    let document = Arc::new(openapi::document(&openapi));
    // The document and its browsable page take no query parameters either: the same layer
    // refuses any. The dashboard's pages (added after) are not the API's and take any.
    let router = router
        .route(
            "/openapi.json",
            get(move || async move { axum::Json(document.as_ref().clone()) }),
        )
        .route("/docs", get(system::docs))
        .route("/docs/rapidoc-min.js", get(system::docs_script))
        .route_layer(axum::middleware::from_fn_with_state(
            (known, Arc::clone(&state.key_owners)),
            known_query::refuse_unknown,
        ));
    router.with_state(state)
}

/// The answers any request may get from the layers around the handlers (`limits`), written into
/// every operation of the document once its paths are all there.
struct EveryRequest;

impl Modify for EveryRequest {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        use error::responses::{BadQuery, BodyTimeout, ForeignName, Unavailable};
        use utoipa::IntoResponses;
        use utoipa::openapi::RefOr;
        let (unavailable, body_timeout) = (Unavailable::responses(), BodyTimeout::responses());
        // Every route refuses a query parameter it does not take (`known_query`).
        let bad_query = BadQuery::responses();
        let foreign_name = ForeignName::responses();
        for item in openapi.paths.paths.values_mut() {
            let operations = [
                &mut item.get,
                &mut item.put,
                &mut item.post,
                &mut item.delete,
                &mut item.patch,
            ];
            for operation in operations.into_iter().flatten() {
                let with_body = operation.request_body.is_some();
                let common = unavailable
                    .iter()
                    .chain(&bad_query)
                    .chain(body_timeout.iter().filter(|_| with_body));
                let responses = &mut operation.responses.responses;
                for (status, response) in common {
                    // An operation's own description of the status stays.
                    responses
                        .entry(status.clone())
                        .or_insert_with(|| response.clone());
                }
                // A 403 of the operation's own (a quota) gets the foreign name's reason too.
                for (status, response) in &foreign_name {
                    match responses.get_mut(status) {
                        Some(RefOr::T(own)) => {
                            if let RefOr::T(foreign) = response {
                                own.description = format!(
                                    "{}; or {}{}",
                                    own.description,
                                    foreign.description[..1].to_lowercase(),
                                    &foreign.description[1..]
                                );
                            }
                        }
                        Some(RefOr::Ref(_)) => {}
                        None => {
                            responses.insert(status.clone(), response.clone());
                        }
                    }
                }
                if responses.contains_key("304") {
                    cache::declare_if_none_match(operation);
                }
            }
        }
    }
}

/// With API keys configured, every /v1 call needs `Authorization: Bearer KEY`; jobs belong to the key.
async fn authenticate(
    State(state): State<AppState>,
    mut request: Request,
    next: Next,
) -> Result<Response, ApiError> {
    let owner = owner_of(request.headers(), &state.key_owners)?;
    request.extensions_mut().insert(owner);
    Ok(next.run(request).await)
}

/// What a request no route takes gets: under `/v1`, 401 without a key the server knows, as every
/// `/v1` route answers (so that no one without a key can map the routes by their 404s and
/// 405s); `otherwise` (404, 405) then, and elsewhere.
fn unmatched(key_owners: &HashSet<Owner>, request: &Request, otherwise: ApiError) -> ApiError {
    let path = request.uri().path();
    let under_v1 = path == "/v1" || path.starts_with("/v1/");
    match owner_of(request.headers(), key_owners) {
        Err(unauthorized) if under_v1 => unauthorized,
        _ => otherwise,
    }
}

/// Whose request it is: the owner of the `Authorization: Bearer KEY` it presents among
/// `key_owners`, or anyone's without API keys; 401 otherwise.
fn owner_of(
    headers: &axum::http::HeaderMap,
    key_owners: &HashSet<Owner>,
) -> Result<Owner, ApiError> {
    if key_owners.is_empty() {
        return Ok(Owner::anonymous());
    }
    let mut given = headers.get_all(header::AUTHORIZATION).iter();
    let first = given.next();
    if given.next().is_some() {
        // Not a list (RFC 9110, section 11.6.2): which one counts is not ours to guess, and taking
        // the first let a client's header win over one a proxy added after it.
        return Err(ApiError::BadRequest(
            "Authorization is given more than once: send one".to_owned(),
        ));
    }
    let presented = first
        .and_then(|value| value.to_str().ok())
        // The scheme is case-insensitive (RFC 9110, section 11.1): `bearer` and `BEARER` count.
        .and_then(|value| value.trim_start().split_once(' '))
        .filter(|(scheme, _)| scheme.eq_ignore_ascii_case("bearer"))
        .map(|(_, token)| token.trim())
        .ok_or(ApiError::Unauthorized)?;
    let owner = Owner::of_key(presented);
    if key_owners.contains(&owner) {
        Ok(owner)
    } else {
        Err(ApiError::Unauthorized)
    }
}

/// The request's `Idempotency-Key`, if it has one, with its body's fingerprint (400 if malformed).
pub fn idempotency_key(
    headers: &axum::http::HeaderMap,
    body: &str,
) -> Result<Option<IdempotencyKey>, ApiError> {
    let mut values = headers.get_all(IDEMPOTENCY_KEY).iter();
    let Some(value) = values.next() else {
        return Ok(None);
    };
    if values.next().is_some() {
        // Which one the client meant is not ours to guess: keying on the first replayed it for a
        // request that sent the first alone.
        return Err(ApiError::BadRequest(
            "Idempotency-Key is given more than once: send one key".to_owned(),
        ));
    }
    let key = value
        .to_str()
        .map_err(|_| ApiError::BadRequest("Idempotency-Key must be visible ASCII".to_owned()))?;
    IdempotencyKey::new(key, body)
        .map(Some)
        .map_err(ApiError::BadRequest)
}

pub const IDEMPOTENCY_KEY: &str = "idempotency-key";

/// A response given again to a retry with the same `Idempotency-Key`: marked as such.
pub fn replayed(mut response: Response) -> Response {
    response.headers_mut().insert(
        axum::http::HeaderName::from_static("idempotent-replayed"),
        axum::http::HeaderValue::from_static("true"),
    );
    response
}

/// Path parameters as axum's `Path` reads them, refused as a problem document (400) rather than
/// axum's plain text: a segment that is not UTF-8 once percent-decoded (`/v1/jobs/%FF`), or one
/// that holds U+0000 (`/v1/jobs/%00`: PostgreSQL refused to compare it, a 503). Named as axum's,
/// so that a handler reads `Path(id): Path<JobId>` either way.
pub struct Path<T>(pub T);

impl<S: Send + Sync, T: serde::de::DeserializeOwned + Send> FromRequestParts<S> for Path<T> {
    type Rejection = ApiError;

    async fn from_request_parts(
        parts: &mut axum::http::request::Parts,
        state: &S,
    ) -> Result<Self, ApiError> {
        let raw = axum::extract::RawPathParams::from_request_parts(parts, state)
            .await
            .map_err(|rejection| ApiError::BadRequest(rejection.body_text()))?;
        if let Some((name, _)) = raw.iter().find(|(_, value)| value.contains('\0')) {
            let rule = bouncewear_model::error::NO_NUL;
            return Err(ApiError::BadRequest(format!("the path's `{name}` {rule}")));
        }
        axum::extract::Path::<T>::from_request_parts(parts, state)
            .await
            .map(|axum::extract::Path(value)| Path(value))
            .map_err(|rejection| ApiError::BadRequest(rejection.body_text()))
    }
}

/// A JSON request body as text: `application/json` in UTF-8 (415 for another type or charset, or
/// for a `Content-Encoding`), at most `max_body_bytes` (413), whole within the body timeout (408),
/// UTF-8 indeed (400). Parsing is left to the model, whose errors name the field.
pub struct JsonText(pub String);

/// Whether a `Content-Type` says JSON in UTF-8: `application/json` or `application/*+json`, with
/// no `charset` parameter or `charset=utf-8` (JSON is UTF-8, RFC 8259 section 8.1).
fn is_utf8_json(content_type: &str) -> bool {
    let mut parts = content_type.split(';');
    let essence = parts.next().unwrap_or("").trim().to_ascii_lowercase();
    let json = essence == "application/json"
        || (essence.starts_with("application/") && essence.ends_with("+json"));
    json && parts.all(|parameter| match parameter.split_once('=') {
        Some((name, value)) if name.trim().eq_ignore_ascii_case("charset") => {
            value.trim().trim_matches('"').eq_ignore_ascii_case("utf-8")
        }
        _ => true,
    })
}

impl FromRequest<AppState> for JsonText {
    type Rejection = ApiError;

    async fn from_request(request: Request, state: &AppState) -> Result<Self, ApiError> {
        // One Content-Type: of two, the first won, whatever the second said (found from outside).
        let mut content_types = request.headers().get_all(header::CONTENT_TYPE).iter();
        let content_type = content_types
            .next()
            .and_then(|v| v.to_str().ok())
            .unwrap_or("");
        if !is_utf8_json(content_type) || content_types.next().is_some() {
            return Err(ApiError::UnsupportedMediaType);
        }
        // A compressed body would be read as its compressed bytes (RFC 7694: 415).
        let encoding = request
            .headers()
            .get(header::CONTENT_ENCODING)
            .map(|v| String::from_utf8_lossy(v.as_bytes()).trim().to_owned());
        if let Some(encoding) = encoding.filter(|e| !e.eq_ignore_ascii_case("identity")) {
            return Err(ApiError::UnsupportedEncoding(encoding));
        }
        let limit = state.config.max_body_bytes;
        // A body declared larger than the limit is refused before any of it is read, not after
        // waiting for bytes a client may never send.
        if limits::declared_over(request.headers(), limit) {
            return Err(ApiError::TooLarge(limit));
        }
        let bytes = Bytes::from_request(request, state)
            .await
            .map_err(|rejection| {
                if rejection.status() == axum::http::StatusCode::PAYLOAD_TOO_LARGE {
                    ApiError::TooLarge(limit)
                } else {
                    ApiError::BadRequest(rejection.body_text())
                }
            })?;
        match std::str::from_utf8(&bytes) {
            // RFC 8259 (8.1) lets a parser ignore a byte-order mark; the command line drops it
            // too, so a file that `bouncewear submit` sends is one a client may post as it is.
            Ok(text) => Ok(JsonText(
                text.strip_prefix('\u{feff}').unwrap_or(text).to_owned(),
            )),
            Err(error) => Err(bouncewear_model::error::not_utf8(&bytes, &error).into()),
        }
    }
}
