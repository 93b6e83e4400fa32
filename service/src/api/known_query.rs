//! Query parameters an operation does not take are refused (400, naming them), not ignored: a
//! misspelt `?quantile=0.99` or a filter the API does not have (`?status=cancelled`) answered as if
//! it were absent would answer a question nobody asked. What each operation takes is read from the
//! OpenAPI document, the one place the parameters are declared.

use super::error::ApiError;
use crate::domain::Owner;
use axum::extract::{MatchedPath, Query, Request, State};
use axum::http::Method;
use axum::middleware::Next;
use axum::response::Response;
use std::collections::{BTreeSet, HashMap, HashSet};
use std::sync::Arc;
use utoipa::openapi::path::{Operation, ParameterIn};
use utoipa::openapi::{OpenApi, RefOr};

/// The query parameters an operation takes; `None` where this does not read them (a reference),
/// and the operation is not checked.
type Takes = Option<BTreeSet<String>>;

/// Each documented operation's query parameters, by method and path template (`/v1/jobs/{id}`).
#[derive(Debug, Clone, Default)]
pub struct KnownQueries(Arc<HashMap<(Method, String), Takes>>);

impl KnownQueries {
    pub fn of(openapi: &OpenApi) -> Self {
        let mut known = HashMap::new();
        for (path, item) in &openapi.paths.paths {
            let operations = [
                (Method::GET, &item.get),
                (Method::PUT, &item.put),
                (Method::POST, &item.post),
                (Method::DELETE, &item.delete),
                (Method::PATCH, &item.patch),
            ];
            for (method, operation) in operations {
                if let Some(operation) = operation {
                    known.insert((method, path.clone()), query_names(operation));
                }
            }
        }
        Self(Arc::new(known))
    }

    /// The parameters of `query` that the operation at `method` and `path` does not take: every
    /// one for a route under this layer that the document does not describe (the document
    /// itself and its page), which take none.
    fn unknown(&self, method: &Method, path: &str, query: &[(String, String)]) -> Vec<String> {
        let names = match self.names(method, path) {
            Some(None) => return Vec::new(),
            Some(Some(names)) => Some(names),
            None => None,
        };
        let unknown: BTreeSet<&String> = query
            .iter()
            .map(|(name, _)| name)
            .filter(|name| !names.is_some_and(|names| names.contains(*name)))
            .collect();
        unknown.into_iter().cloned().collect()
    }

    fn takes(&self, method: &Method, path: &str) -> Vec<String> {
        self.names(method, path)
            .flatten()
            .map(|names| names.iter().cloned().collect())
            .unwrap_or_default()
    }

    /// The operation's parameters (a HEAD is its GET's); `None` for a route the document does
    /// not describe.
    fn names(&self, method: &Method, path: &str) -> Option<Option<&BTreeSet<String>>> {
        let method = if method == Method::HEAD {
            Method::GET
        } else {
            method.clone()
        };
        self.0.get(&(method, path.to_owned())).map(Option::as_ref)
    }
}

/// The operation's query parameters; `None` (not checked) if one is a reference this does not
/// follow.
fn query_names(operation: &Operation) -> Option<BTreeSet<String>> {
    let mut names = BTreeSet::new();
    for parameter in operation.parameters.iter().flatten() {
        let RefOr::T(parameter) = parameter else {
            return None;
        };
        if matches!(parameter.parameter_in, ParameterIn::Query) {
            names.insert(parameter.name.clone());
        }
    }
    Some(names)
}

/// Answers 400 naming every query parameter the matched operation does not take; under `/v1`,
/// 401 first without a key the server knows, as the route itself answers (a request without one
/// learns nothing of what a route takes).
pub async fn refuse_unknown(
    State((known, key_owners)): State<(KnownQueries, Arc<HashSet<Owner>>)>,
    path: MatchedPath,
    request: Request,
    next: Next,
) -> Result<Response, ApiError> {
    if let Err(refused) = check(&known, path.as_str(), &request) {
        return Err(super::unmatched(&key_owners, &request, refused));
    }
    Ok(next.run(request).await)
}

/// 400 for a query that cannot be read or that names a parameter the operation does not take.
fn check(known: &KnownQueries, path: &str, request: &Request) -> Result<(), ApiError> {
    if request.uri().query().is_some() {
        let Query(query) =
            Query::<Vec<(String, String)>>::try_from_uri(request.uri()).map_err(ApiError::from)?;
        let unknown = known.unknown(request.method(), path, &query);
        if !unknown.is_empty() {
            let quoted = |names: &[String]| {
                names
                    .iter()
                    .map(|n| format!("`{n}`"))
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            let takes = known.takes(request.method(), path);
            let takes = if takes.is_empty() {
                "no query parameters".to_owned()
            } else {
                format!("only {}", quoted(&takes))
            };
            return Err(ApiError::BadRequest(format!(
                "unknown query parameter {}: {} {path} takes {takes}",
                quoted(&unknown),
                request.method(),
            )));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_the_declared_query_parameters_pass_and_head_is_get() {
        let distribution = "/v1/jobs/{id}/distributions/{metric}";
        let known = KnownQueries(Arc::new(HashMap::from([
            (
                (Method::GET, distribution.to_owned()),
                Some(BTreeSet::from([
                    "quantiles".to_owned(),
                    "op_start".to_owned(),
                ])),
            ),
            (
                (Method::GET, "/v1/jobs/{id}".to_owned()),
                Some(BTreeSet::new()),
            ),
            ((Method::GET, "/v1/unread".to_owned()), None),
        ])));
        let query = |pairs: &[(&str, &str)]| -> Vec<(String, String)> {
            pairs
                .iter()
                .map(|(k, v)| ((*k).to_owned(), (*v).to_owned()))
                .collect()
        };
        let ok = query(&[("quantiles", "0.5"), ("op_start", "3")]);
        assert!(known.unknown(&Method::GET, distribution, &ok).is_empty());
        let misspelt = query(&[("thresholds", "0.011"), ("quantiles", "0.5"), ("a", "")]);
        assert_eq!(
            known.unknown(&Method::HEAD, distribution, &misspelt),
            ["a", "thresholds"]
        );
        assert_eq!(
            known.unknown(&Method::GET, "/v1/jobs/{id}", &query(&[("x", "1")])),
            ["x"]
        );
        // A route the document does not describe takes none.
        let undocumented = known.unknown(&Method::GET, "/jobs/{id}", &query(&[("x", "1")]));
        assert_eq!(undocumented, ["x"]);
        // An operation whose parameters are a reference this does not follow is not checked.
        assert!(
            known
                .unknown(&Method::GET, "/v1/unread", &query(&[("x", "1")]))
                .is_empty()
        );
    }
}
