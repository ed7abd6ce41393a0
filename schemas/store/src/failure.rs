//! An object store that failed a request after its client's retries ([`StoreFailure`]): not
//! the reader's fault, and told apart from a store that could not be reached. A server answers
//! 502 for the one and 503 for the other, whichever layer (zarrs, the pyramid reader) the
//! failure came through: it travels inside zarrs' storage errors ([`StoreFailure::into_storage`])
//! and is found again in any chain of causes ([`StoreFailure::in_chain`]).

use std::error::Error;
use std::sync::Arc;

use zarrs_object_store::object_store;
use zarrs_storage::StorageError;

/// A request to an object store that failed after its client's retries.
#[derive(Debug, thiserror::Error)]
#[error("{} ({source})", if *unreachable { "the object store did not answer" } else { "the object store answered an error" })]
pub struct StoreFailure {
    /// Whether the store could not be reached or timed out, rather than answered an error.
    pub unreachable: bool,
    /// What the object-store client said.
    #[source]
    pub source: Box<dyn Error + Send + Sync>,
}

impl StoreFailure {
    /// The failure of a request that did not find a missing object: unreachable when the
    /// connection failed, was reset or timed out, and an error answer otherwise (a 5xx, a
    /// refusal, a malformed answer).
    pub fn of_request(e: object_store::Error) -> Self {
        let mut unreachable = false;
        let mut cause: Option<&(dyn Error + 'static)> = Some(&e);
        while let Some(c) = cause {
            if let Some(http) = c.downcast_ref::<object_store::client::HttpError>() {
                use object_store::client::HttpErrorKind as Kind;
                unreachable |= matches!(
                    http.kind(),
                    Kind::Connect | Kind::Request | Kind::Timeout | Kind::Interrupted
                );
            }
            cause = c.source();
        }
        Self {
            unreachable,
            source: e.into(),
        }
    }

    /// This failure as a zarrs storage error, which keeps it among its causes (zarrs' storage
    /// errors carry structure only as I/O errors).
    pub fn into_storage(self) -> StorageError {
        StorageError::IOError(Arc::new(std::io::Error::other(Carried(self))))
    }

    /// The failure among `why` and its causes, if any.
    pub fn in_chain<'a>(why: &'a (dyn Error + 'static)) -> Option<&'a Self> {
        let mut cause = Some(why);
        while let Some(c) = cause {
            if let Some(failure) = c.downcast_ref::<Self>() {
                return Some(failure);
            }
            cause = c.source();
        }
        None
    }
}

/// A failure inside an I/O error. An I/O error gives its content's cause as its own, and
/// zarrs' storage error gives the I/O error's: so the content names the failure as its cause,
/// and a walk down the causes of any error that holds it meets it.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
struct Carried(#[source] StoreFailure);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failure_carried_by_zarrs_is_found_and_named() {
        let failure = StoreFailure {
            unreachable: true,
            source: "connection reset".into(),
        };
        let storage = failure.into_storage();
        assert_eq!(
            storage.to_string(),
            "the object store did not answer (connection reset)"
        );
        let found = StoreFailure::in_chain(&storage).expect("carried");
        assert!(found.unreachable);
        // Behind more layers, as zarrs and the pyramid reader wrap it.
        #[derive(Debug, thiserror::Error)]
        #[error("cannot open level 0: {0}")]
        struct Outer(#[source] StorageError);
        let outer = Outer(storage);
        assert!(StoreFailure::in_chain(&outer).is_some());
        assert!(StoreFailure::in_chain(&std::io::Error::other("disk")).is_none());
    }
}
