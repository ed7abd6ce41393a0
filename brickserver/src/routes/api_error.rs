//! The JSON error answers of the region and brick API ([`ApiError`]), and the status of an
//! answer that failed: 502/503 when the object store failed, 500 when the server did.

use axum::body::Body;
use axum::http::{Response, StatusCode, header};
use axum::response::{IntoResponse, Json};
use residency_schemas::server::ApiError;

use crate::store_keys::StoreFailure;

/// Seconds a client is asked to wait (`Retry-After`) before it tries again when the object
/// store did not answer.
pub(super) const RETRY_AFTER_S: &str = "5";

/// The status of an answer that failed because of `why`: 503 when an object store did not
/// answer, 502 when it answered an error (a [`StoreFailure`] anywhere in `why`'s chain), else
/// 500 (the server's own fault).
pub(super) fn failure_status(why: &(dyn std::error::Error + 'static)) -> StatusCode {
    match StoreFailure::in_chain(why) {
        Some(failure) if failure.unreachable => StatusCode::SERVICE_UNAVAILABLE,
        Some(_) => StatusCode::BAD_GATEWAY,
        None => StatusCode::INTERNAL_SERVER_ERROR,
    }
}

/// The text answer for a key that cannot be read because of `why`: `message` (which names the
/// key) with [`failure_status`], and `Retry-After` on a 503; logged.
pub(super) fn unreadable_key(
    message: &str,
    why: &(dyn std::error::Error + 'static),
) -> Response<Body> {
    let status = failure_status(why);
    if status == StatusCode::INTERNAL_SERVER_ERROR {
        tracing::error!("{message}");
    } else {
        tracing::warn!("{message}");
    }
    let mut answer = (status, format!("{message}\n")).into_response();
    if status == StatusCode::SERVICE_UNAVAILABLE {
        answer.headers_mut().insert(
            header::RETRY_AFTER,
            header::HeaderValue::from_static(RETRY_AFTER_S),
        );
    }
    answer
}

/// The JSON answer for a dataset whose arrays or region metadata cannot be loaded because of
/// `why`: [`failure_status`], with `Retry-After` on a 503.
pub(super) fn load_failed(why: &(dyn std::error::Error + 'static)) -> Response<Body> {
    let status = failure_status(why);
    if status != StatusCode::INTERNAL_SERVER_ERROR {
        tracing::warn!("{why}");
    }
    let mut answer = api_error(status, why.to_string());
    if status == StatusCode::SERVICE_UNAVAILABLE {
        answer.headers_mut().insert(
            header::RETRY_AFTER,
            header::HeaderValue::from_static(RETRY_AFTER_S),
        );
    }
    answer
}

/// A JSON error answer (logged when it is the server's fault).
pub(super) fn api_error(status: StatusCode, error: String) -> Response<Body> {
    if status.is_server_error() {
        tracing::error!("{error}");
    }
    (status, Json(ApiError { error })).into_response()
}

/// The answer for a dataset that is not served.
pub(super) fn no_dataset(name: &str) -> Response<Body> {
    api_error(StatusCode::NOT_FOUND, format!("no dataset '{name}'"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn store_failures_are_502_or_503_and_the_servers_own_500() {
        let failure = |unreachable| StoreFailure {
            unreachable,
            source: "upstream".into(),
        };
        let gone = unreadable_key("cannot read key 'k'", &failure(true));
        assert_eq!(gone.status(), StatusCode::SERVICE_UNAVAILABLE);
        assert_eq!(gone.headers()[header::RETRY_AFTER], "5");
        let answered = unreadable_key("cannot read key 'k'", &failure(false));
        assert_eq!(answered.status(), StatusCode::BAD_GATEWAY);
        assert!(!answered.headers().contains_key(header::RETRY_AFTER));
        let ours = unreadable_key("cannot read key 'k'", &std::io::Error::other("disk"));
        assert_eq!(ours.status(), StatusCode::INTERNAL_SERVER_ERROR);
        // Found anywhere in the chain, as when a load error wraps it.
        #[derive(Debug, thiserror::Error)]
        #[error("loading failed")]
        struct Wrapped(#[source] StoreFailure);
        assert_eq!(
            failure_status(&Wrapped(failure(true))),
            StatusCode::SERVICE_UNAVAILABLE
        );
        // Inside a zarrs storage error, as an array or region metadata load meets it.
        let loading = failure(true).into_storage();
        let answer = load_failed(&loading);
        assert_eq!(answer.status(), StatusCode::SERVICE_UNAVAILABLE);
        assert_eq!(answer.headers()[header::RETRY_AFTER], "5");
        assert_eq!(
            load_failed(&failure(false).into_storage()).status(),
            StatusCode::BAD_GATEWAY
        );
        assert_eq!(
            load_failed(&std::io::Error::other("disk")).status(),
            StatusCode::INTERNAL_SERVER_ERROR
        );
    }
}
