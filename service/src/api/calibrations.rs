//! `POST /v1/calibrations`: a scenario fitted to measured operations, as `bouncewear calibrate`
//! prints it (docs/model.md section 10).

use super::error::{
    ApiError, Internal,
    responses::{BadQuery, BodyRejected, Unauthorized},
};
use super::{AppState, JsonText};
use crate::plots::{calibration_panels, calibration_svg};
use axum::Json;
use axum::extract::rejection::QueryRejection;
use axum::extract::{Query, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use bouncewear_model::calibration::{Calibration, CalibrationSpec, calibrate_until};
use serde::Deserialize;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use tokio::sync::Semaphore;
use utoipa::{IntoParams, ToSchema};
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(create_calibration))
}

/// Places for fits, one per core: fits run off the async runtime, each holding its place until
/// it ends, and the rest wait their turn within the request timeout. A fit is bounded (at most
/// 1000 observations and 8 parameters) but may take minutes along wear curves: at the request
/// timeout (503) it is stopped (`StopOnDrop`) and gives its place back within about one
/// evaluation, never before, so that clients who let requests time out can neither pile up fits
/// beyond the cores nor keep them busy past the timeout. (A client that closes its connection
/// is not noticed before the timeout: hyper does not read a connection while it answers.)
pub fn places_for_fits() -> Arc<Semaphore> {
    super::limits::places_per_core()
}

/// Cancels a fit when dropped: when its handler ends, answered or not (the request timeout drops
/// it unanswered).
struct StopOnDrop(Arc<AtomicBool>);

impl Drop for StopOnDrop {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Relaxed);
    }
}

/// The representation of a calibration.
#[derive(Debug, Clone, Copy, Default, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum CalibrationFormat {
    /// The estimates, fitted scenario, residuals and readings.
    #[default]
    Json,
    /// The fit as a plot: simulated against measured, a panel per quantity.
    Svg,
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct CalibrationQuery {
    /// `json` (default) or `svg` (the plot of the fit).
    #[param(inline, example = "json")]
    pub format: Option<CalibrationFormat>,
}

/// Fit a scenario to measured operations.
///
/// Least squares in the parameters' logarithms, each observation simulated at its own measured
/// impact velocity: estimates with 95 % intervals, the fitted scenario ready to submit as a job,
/// the residuals, and the paper's readings of e off bounce times with their bias under the fitted
/// model. Synchronous. A parameter the measurements cannot determine is refused with 422 naming
/// its place in `fit`. `format=svg` gives the fit as a plot instead.
#[utoipa::path(
    post, path = "/v1/calibrations", tag = "calibrations",
    params(CalibrationQuery),
    request_body(content = CalibrationSpec, description = "The starting scenario, the parameters to fit and the measured operations (docs/model.md section 10)", content_type = "application/json"),
    responses(
        (status = 200, description = "The fit (JSON), or with `format=svg` its plot", content((Calibration = "application/json"), (String = "image/svg+xml"))),
        BadQuery,
        BodyRejected,
        Unauthorized,
    ),
    security((), ("api_key" = []))
)]
pub async fn create_calibration(
    State(state): State<AppState>,
    query: Result<Query<CalibrationQuery>, QueryRejection>,
    JsonText(body): JsonText,
) -> Result<Response, ApiError> {
    let Query(query) = query?;
    let spec = CalibrationSpec::from_json(&body)?;
    let place = super::limits::take_place(&state.fits).await?;
    let stop = StopOnDrop(Arc::new(AtomicBool::new(false)));
    let cancel = Arc::clone(&stop.0);
    let (spec, fit) = tokio::task::spawn_blocking(move || {
        let _place = place;
        let fit = calibrate_until(&spec, &cancel);
        if fit.is_err() {
            metrics::counter!(crate::telemetry::FITS_STOPPED).increment(1);
        }
        (spec, fit)
    })
    .await
    .map_err(|e| Internal(format!("a calibration failed: {e}")))?;
    // Not cancelled: `stop` lives until here, and the fit has ended.
    let fit = fit.map_err(|cancelled| Internal(cancelled.to_string()))??;
    Ok(match query.format.unwrap_or_default() {
        CalibrationFormat::Json => Json(fit).into_response(),
        CalibrationFormat::Svg => (
            [(header::CONTENT_TYPE, "image/svg+xml")],
            calibration_svg(&calibration_panels(&spec, &fit)),
        )
            .into_response(),
    })
}
