//! Reading an object store through zarrs with one request per read: each byte range zarrs
//! asks for (a brick, a shard index, a suffix) is one ranged `GET`. `zarrs_object_store`
//! asks for the object's size with a `HEAD` before every partial read, so a brick of a sharded
//! store cost a `HEAD` and a `GET` for the shard index and again for the brick. Listing is
//! `zarrs_object_store`'s. A failed request is a [`StoreFailure`] inside zarrs' error.

use std::sync::Arc;

use futures::{StreamExt, TryStreamExt, stream};

use crate::failure::StoreFailure;
use zarrs_object_store::AsyncObjectStore;
use zarrs_object_store::object_store::path::Path as ObjectPath;
use zarrs_object_store::object_store::{GetOptions, GetRange, ObjectStore};
use zarrs_storage::byte_range::{ByteRange, ByteRangeIterator};
use zarrs_storage::{
    AsyncListableStorageTraits, AsyncMaybeBytesIterator, AsyncReadableStorageTraits, Bytes,
    MaybeBytes, StorageError, StoreKey, StoreKeys, StoreKeysPrefixes, StorePrefix,
};

/// An object store read by zarrs with ranged `GET`s only (no `HEAD` before a partial read).
pub struct RangedObjectStore {
    store: Arc<dyn ObjectStore>,
    listing: AsyncObjectStore<Arc<dyn ObjectStore>>,
}

impl RangedObjectStore {
    /// Reads `store` (keys relative to its root: wrap it in a `PrefixStore` for a prefix).
    pub fn new(store: Arc<dyn ObjectStore>) -> Self {
        Self {
            listing: AsyncObjectStore::new(Arc::clone(&store)),
            store,
        }
    }

    /// The bytes of `range` of `key` (`None`: no such key) in one request; a range that asks
    /// for nothing makes no request.
    async fn get_range(
        &self,
        key: &StoreKey,
        range: Option<GetRange>,
    ) -> Result<MaybeBytes, StorageError> {
        let expected = match &range {
            Some(GetRange::Bounded(r)) if r.is_empty() => return Ok(Some(Bytes::new())),
            Some(GetRange::Suffix(0)) => return Ok(Some(Bytes::new())),
            Some(GetRange::Bounded(r)) => Some(r.end - r.start),
            Some(GetRange::Suffix(n)) => Some(*n),
            _ => None,
        };
        let options = GetOptions {
            range,
            ..GetOptions::default()
        };
        let got = match self
            .store
            .get_opts(&ObjectPath::from(key.as_str()), options)
            .await
        {
            Ok(got) => got,
            Err(zarrs_object_store::object_store::Error::NotFound { .. }) => return Ok(None),
            Err(e) => return Err(StoreFailure::of_request(e).into_storage()),
        };
        let bytes = got
            .bytes()
            .await
            .map_err(|e| StoreFailure::of_request(e).into_storage())?;
        // A bounded range past the end, or a suffix longer than the object, comes back short.
        if let Some(n) = expected
            && bytes.len() as u64 != n
        {
            return Err(StoreFailure {
                unreachable: false,
                source: format!(
                    "{key}: asked for {n} bytes, the store answered {}",
                    bytes.len()
                )
                .into(),
            }
            .into_storage());
        }
        Ok(Some(bytes))
    }
}

/// The request for `range`: `None` for the whole object.
fn get_range(range: ByteRange) -> Option<GetRange> {
    match range {
        ByteRange::FromStart(0, None) => None,
        ByteRange::FromStart(offset, None) => Some(GetRange::Offset(offset)),
        ByteRange::FromStart(offset, Some(length)) => {
            Some(GetRange::Bounded(offset..offset + length))
        }
        ByteRange::Suffix(length) => Some(GetRange::Suffix(length)),
    }
}

#[async_trait::async_trait]
impl AsyncReadableStorageTraits for RangedObjectStore {
    async fn get(&self, key: &StoreKey) -> Result<MaybeBytes, StorageError> {
        self.get_range(key, None).await
    }

    async fn get_partial_many<'a>(
        &'a self,
        key: &StoreKey,
        byte_ranges: ByteRangeIterator<'a>,
    ) -> Result<AsyncMaybeBytesIterator<'a>, StorageError> {
        // Every range at once; a missing key is missing for all of them.
        let parts = stream::iter(byte_ranges.map(|r| self.get_range(key, get_range(r))))
            .buffered(16)
            .try_collect::<Vec<_>>()
            .await?;
        let Some(parts) = parts.into_iter().collect::<Option<Vec<_>>>() else {
            return Ok(None);
        };
        Ok(Some(stream::iter(parts.into_iter().map(Ok)).boxed()))
    }

    async fn size_key(&self, key: &StoreKey) -> Result<Option<u64>, StorageError> {
        self.listing.size_key(key).await
    }

    fn supports_get_partial(&self) -> bool {
        true
    }
}

#[async_trait::async_trait]
impl AsyncListableStorageTraits for RangedObjectStore {
    async fn list(&self) -> Result<StoreKeys, StorageError> {
        self.listing.list().await
    }

    async fn list_prefix(&self, prefix: &StorePrefix) -> Result<StoreKeys, StorageError> {
        self.listing.list_prefix(prefix).await
    }

    async fn list_dir(&self, prefix: &StorePrefix) -> Result<StoreKeysPrefixes, StorageError> {
        self.listing.list_dir(prefix).await
    }

    async fn size_prefix(&self, prefix: &StorePrefix) -> Result<u64, StorageError> {
        self.listing.size_prefix(prefix).await
    }
}

#[cfg(test)]
mod tests {
    use std::fmt;
    use std::sync::atomic::{AtomicUsize, Ordering};

    use futures::stream::BoxStream;
    use zarrs::storage::storage_adapter::async_to_sync::{
        AsyncToSyncBlockOn, AsyncToSyncStorageAdapter,
    };
    use zarrs_object_store::object_store::memory::InMemory;
    use zarrs_object_store::object_store::{
        CopyOptions, GetResult, ListResult, MultipartUpload, ObjectMeta, ObjectStoreExt,
        PutMultipartOptions, PutOptions, PutPayload, PutResult, Result,
    };
    use zarrs_storage::ReadableStorageTraits;

    use super::*;

    /// An in-memory store that counts the `HEAD`s and `GET`s made of it.
    #[derive(Debug, Default)]
    struct Counting {
        inner: InMemory,
        heads: AtomicUsize,
        gets: AtomicUsize,
    }

    impl fmt::Display for Counting {
        fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
            write!(f, "Counting({})", self.inner)
        }
    }

    #[async_trait::async_trait]
    impl ObjectStore for Counting {
        async fn put_opts(
            &self,
            p: &ObjectPath,
            b: PutPayload,
            o: PutOptions,
        ) -> Result<PutResult> {
            self.inner.put_opts(p, b, o).await
        }

        async fn put_multipart_opts(
            &self,
            p: &ObjectPath,
            o: PutMultipartOptions,
        ) -> Result<Box<dyn MultipartUpload>> {
            self.inner.put_multipart_opts(p, o).await
        }

        async fn get_opts(&self, p: &ObjectPath, o: GetOptions) -> Result<GetResult> {
            let counter = if o.head { &self.heads } else { &self.gets };
            counter.fetch_add(1, Ordering::SeqCst);
            self.inner.get_opts(p, o).await
        }

        fn delete_stream(
            &self,
            locations: BoxStream<'static, Result<ObjectPath>>,
        ) -> BoxStream<'static, Result<ObjectPath>> {
            self.inner.delete_stream(locations)
        }

        fn list(&self, prefix: Option<&ObjectPath>) -> BoxStream<'static, Result<ObjectMeta>> {
            self.inner.list(prefix)
        }

        async fn list_with_delimiter(&self, prefix: Option<&ObjectPath>) -> Result<ListResult> {
            self.inner.list_with_delimiter(prefix).await
        }

        async fn copy_opts(
            &self,
            from: &ObjectPath,
            to: &ObjectPath,
            o: CopyOptions,
        ) -> Result<()> {
            self.inner.copy_opts(from, to, o).await
        }
    }

    struct Runtime(tokio::runtime::Runtime);

    impl AsyncToSyncBlockOn for Runtime {
        fn block_on<F: Future>(&self, future: F) -> F::Output {
            self.0.block_on(future)
        }
    }

    #[test]
    fn every_read_is_one_ranged_get_without_a_head() {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        let counting = Arc::new(Counting::default());
        let bytes: Vec<u8> = (0..100u8).collect();
        runtime
            .block_on(counting.put(&ObjectPath::from("a/c/0"), bytes.clone().into()))
            .unwrap();
        let store: Arc<dyn ObjectStore> = counting.clone();
        let storage = AsyncToSyncStorageAdapter::new(
            Arc::new(RangedObjectStore::new(store)),
            Runtime(runtime),
        );
        let key = StoreKey::new("a/c/0").unwrap();
        let counts = || {
            (
                counting.heads.load(Ordering::SeqCst),
                counting.gets.load(Ordering::SeqCst),
            )
        };
        assert_eq!(storage.get(&key).unwrap().unwrap(), bytes);
        assert_eq!(counts(), (0, 1));
        let ranges = [
            ByteRange::FromStart(10, Some(5)),
            ByteRange::FromStart(95, None),
            ByteRange::Suffix(3),
            ByteRange::FromStart(0, None),
        ];
        let parts = storage
            .get_partial_many(&key, Box::new(ranges.into_iter()))
            .unwrap()
            .unwrap()
            .collect::<std::result::Result<Vec<_>, _>>()
            .unwrap();
        assert_eq!(parts[0], bytes[10..15]);
        assert_eq!(parts[1], bytes[95..]);
        assert_eq!(parts[2], bytes[97..]);
        assert_eq!(parts[3], bytes);
        assert_eq!(counts(), (0, 5), "one GET per range, no HEAD");
        // An empty range asks for nothing; a missing key is missing.
        let empty = storage
            .get_partial(&key, ByteRange::FromStart(4, Some(0)))
            .unwrap();
        assert_eq!(empty.unwrap().len(), 0);
        let gone = StoreKey::new("a/c/1").unwrap();
        assert_eq!(storage.get(&gone).unwrap(), None);
        assert_eq!(
            storage
                .get_partial(&gone, ByteRange::FromStart(0, Some(4)))
                .unwrap(),
            None
        );
        assert_eq!(counts(), (0, 7));
        // A range past the end is refused, not returned short.
        let err = storage
            .get_partial(&key, ByteRange::FromStart(90, Some(20)))
            .unwrap_err();
        assert_eq!(
            err.to_string(),
            "the object store answered an error (a/c/0: asked for 20 bytes, the store answered 10)"
        );
        let failure = StoreFailure::in_chain(&err).expect("a store failure");
        assert!(!failure.unreachable);
        // The size is the one read that asks for it.
        assert_eq!(storage.size_key(&key).unwrap(), Some(100));
        assert_eq!(counts(), (1, 8));
    }
}
