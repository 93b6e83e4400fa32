//! `POST /v1/simulate`: one make operation, as `bouncewear simulate` prints it.

use super::error::{
    ApiError,
    responses::{BodyRejected, Unauthorized},
};
use super::{AppState, JsonText};
use axum::Json;
use axum::extract::Query;
use axum::extract::rejection::QueryRejection;
use bouncewear_model::{Fidelity, Scenario, ScenarioSpec, Simulation, simulate};
use serde::Deserialize;
use utoipa::IntoParams;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(simulate_operation))
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct SimulateQuery {
    /// `exact` (default) or `closed_form`.
    #[param(inline, example = "exact")]
    pub fidelity: Option<Fidelity>,
}

/// Simulate one make operation of a scenario.
///
/// Runs the model once, synchronously, for the given scenario (every field optional; the empty
/// document is the paper's rig): the outcome of the operation and each bounce. The same output as
/// `bouncewear simulate`.
#[utoipa::path(
    post, path = "/v1/simulate", tag = "simulate",
    params(SimulateQuery),
    request_body(content = ScenarioSpec, description = "A scenario; every field optional (docs/model.md section 8)", content_type = "application/json"),
    responses(
        (status = 200, description = "The operation and its bounces", body = Simulation),
        BodyRejected,
        Unauthorized,
    ),
    security((), ("api_key" = []))
)]
pub async fn simulate_operation(
    query: Result<Query<SimulateQuery>, QueryRejection>,
    JsonText(body): JsonText,
) -> Result<Json<Simulation>, ApiError> {
    let Query(query) = query?;
    let scenario = Scenario::from_json(&body)?;
    Ok(Json(simulate(
        &scenario,
        query.fidelity.unwrap_or_default(),
    )))
}
