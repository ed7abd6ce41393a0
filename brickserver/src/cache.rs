//! A bounded in-memory cache of bricks served in batches (decoded samples, or stored bytes cut
//! out of shards) and of chunk objects read whole from an object store, with their `ETag`. Its
//! size never exceeds the configured byte budget (`--cache-bytes`); entries are evicted by
//! quick_cache's CLOCK-PRO policy. Hits and misses are counted in the metrics.

use std::sync::Arc;
use std::time::Instant;

use axum::body::Bytes;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::gauge::Gauge;
use quick_cache::Weighter;
use quick_cache::sync::Cache;

/// What an entry holds.
#[derive(Clone, Debug, Hash, PartialEq, Eq)]
pub(crate) enum CacheKey {
    /// A brick of a batch: dataset (index in the served list), level, channel, brick
    /// coordinates `z, y, x`, and whether it holds decoded samples (`raw`) or stored bytes.
    Brick {
        /// Dataset index.
        dataset: usize,
        /// The generation of the dataset the batch's arrays read (how many times its folder
        /// had been replaced whole).
        generation: u64,
        /// Level, channel and brick coordinates `z, y, x`.
        at: (u32, u32, [u64; 3]),
        /// Decoded samples rather than stored bytes.
        raw: bool,
    },
    /// A chunk object of a dataset in an object store, at its (still percent-encoded) key.
    Object {
        /// Dataset index.
        dataset: usize,
        /// The key under the dataset's root.
        key: String,
    },
}

/// A cached value: the bytes (empty for an empty brick) and, for an object, its `ETag` and
/// when it was read.
#[derive(Clone, Debug)]
pub(crate) struct Cached {
    /// The bytes.
    pub(crate) bytes: Bytes,
    /// The object's `ETag` and when it was read (`None` for a brick).
    pub(crate) etag: Option<(Arc<str>, Instant)>,
}

#[derive(Clone)]
struct ByteWeight;

impl Weighter<CacheKey, Cached> for ByteWeight {
    fn weight(&self, key: &CacheKey, value: &Cached) -> u64 {
        // Count the bookkeeping too, so many empty bricks cannot exceed the budget.
        let key_bytes = match key {
            CacheKey::Brick { .. } => 0,
            CacheKey::Object { key, .. } => key.len(),
        };
        (value.bytes.len() + key_bytes + 96) as u64
    }
}

/// The bounded cache, with its hit and miss counters.
pub(crate) struct ByteCache {
    inner: Option<Cache<CacheKey, Cached, ByteWeight>>,
    hits: Counter,
    misses: Counter,
    bytes: Gauge,
}

impl ByteCache {
    /// A cache holding at most `capacity` bytes (0 turns caching off), counting into the
    /// given metrics.
    pub(crate) fn new(capacity: u64, hits: Counter, misses: Counter, bytes: Gauge) -> Self {
        let inner = (capacity > 0).then(|| {
            // Estimate the entry count from a typical 64 KiB brick.
            let items = (capacity / 65536).clamp(16, 1 << 20) as usize;
            Cache::with_weighter(items, capacity, ByteWeight)
        });
        Self {
            inner,
            hits,
            misses,
            bytes,
        }
    }

    /// The cached entry for `key`, counting a hit or a miss.
    pub(crate) fn get(&self, key: &CacheKey) -> Option<Cached> {
        let found = self.inner.as_ref().and_then(|c| c.get(key));
        if found.is_some() {
            self.hits.inc();
        } else {
            self.misses.inc();
        }
        found
    }

    /// Forgets every entry of dataset `index` (its folder was replaced).
    pub(crate) fn forget_dataset(&self, index: usize) {
        if let Some(c) = &self.inner {
            c.retain(|key, _| match key {
                CacheKey::Brick { dataset, .. } | CacheKey::Object { dataset, .. } => {
                    *dataset != index
                }
            });
            self.bytes.set(c.weight() as i64);
        }
    }

    /// Stores an entry (an entry larger than the whole budget is not kept).
    pub(crate) fn insert(&self, key: CacheKey, value: Cached) {
        if let Some(c) = &self.inner {
            c.insert(key, value);
            self.bytes.set(c.weight() as i64);
        }
    }

    /// Bytes held now.
    #[cfg(test)]
    pub(crate) fn weight(&self) -> u64 {
        self.inner.as_ref().map_or(0, Cache::weight)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn never_holds_more_than_its_budget() {
        let (hits, misses) = (Counter::default(), Counter::default());
        let cache = ByteCache::new(100_000, hits.clone(), misses.clone(), Gauge::default());
        let key = |i: u64| CacheKey::Brick {
            dataset: 0,
            generation: 0,
            at: (0, 0, [0, 0, i]),
            raw: true,
        };
        let value = |bytes: Bytes| Cached { bytes, etag: None };
        for i in 0..1000 {
            cache.insert(key(i), value(Bytes::from(vec![0u8; 1000])));
            assert!(cache.weight() <= 100_000, "{}", cache.weight());
        }
        assert!(cache.get(&key(999)).is_some());
        assert!((0..1000).filter(|&i| cache.get(&key(i)).is_some()).count() < 100);
        assert_eq!(hits.get() + misses.get(), 1001);
        let off = ByteCache::new(0, hits, misses.clone(), Gauge::default());
        off.insert(key(1), value(Bytes::from_static(b"x")));
        assert!(off.get(&key(1)).is_none());
    }
}
