//! A blocking HTTP client that never turns a status into an error, and the checks every problem
//! document must pass.

use serde_json::Value;
use std::time::Duration;

pub fn agent() -> ureq::Agent {
    ureq::Agent::config_builder()
        .http_status_as_error(false)
        .timeout_global(Some(Duration::from_secs(60)))
        .build()
        .into()
}

/// A response, read whole.
pub struct Reply {
    pub status: u16,
    pub content_type: String,
    pub headers: ureq::http::HeaderMap,
    pub body: String,
}

impl Reply {
    pub fn json(&self) -> Value {
        serde_json::from_str(&self.body).unwrap_or_else(|e| panic!("{e}: {}", self.body))
    }

    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers.get(name).and_then(|v| v.to_str().ok())
    }
}

pub fn reply(response: Result<ureq::http::Response<ureq::Body>, ureq::Error>) -> Reply {
    let mut response = response.expect("the server answers");
    let content_type = response
        .headers()
        .get("content-type")
        .and_then(|v| v.to_str().ok())
        .unwrap_or("")
        .to_owned();
    Reply {
        status: response.status().as_u16(),
        content_type,
        headers: response.headers().clone(),
        body: response
            .body_mut()
            .with_config()
            .limit(1 << 28)
            .read_to_string()
            .unwrap(),
    }
}

/// `request` with `Authorization: Bearer KEY` when there is a key.
pub fn authorized<B>(
    request: ureq::RequestBuilder<B>,
    key: Option<&str>,
) -> ureq::RequestBuilder<B> {
    match key {
        Some(key) => request.header("authorization", &format!("Bearer {key}")),
        None => request,
    }
}

pub fn get(url: &str, key: Option<&str>) -> Reply {
    reply(authorized(agent().get(url), key).call())
}

pub fn post(url: &str, body: &str, key: Option<&str>) -> Reply {
    let request = agent().post(url).header("content-type", "application/json");
    reply(authorized(request, key).send(body))
}

pub fn put(url: &str, body: &str) -> Reply {
    reply(
        agent()
            .put(url)
            .header("content-type", "application/json")
            .send(body),
    )
}

pub fn delete(url: &str) -> Reply {
    reply(agent().delete(url).call())
}

/// Checks that `reply` is an RFC 9457 problem with `status` whose detail says `words`, and
/// returns it.
pub fn assert_problem_saying(reply: &Reply, status: u16, words: &str) -> Value {
    let problem = assert_problem(reply, status);
    assert!(
        problem["detail"].as_str().unwrap().contains(words),
        "{words} in {problem}"
    );
    problem
}

/// Checks that `reply` is an RFC 9457 problem with `status`, and returns it.
pub fn assert_problem(reply: &Reply, status: u16) -> Value {
    assert_eq!(reply.status, status, "{}", reply.body);
    assert_eq!(
        reply.content_type, "application/problem+json",
        "{}",
        reply.body
    );
    let problem = reply.json();
    assert_eq!(problem["status"], status);
    assert!(problem["title"].is_string() && problem["detail"].is_string());
    problem
}
