//! A bounded in-memory cache of served bytes: chunk files read from disk and bricks decoded
//! for batches. Its size never exceeds the configured byte budget (`--cache-bytes`); entries
//! are evicted by quick_cache's CLOCK-PRO policy. Hits and misses are counted in the metrics.

use std::sync::Arc;

use axum::body::Bytes;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::gauge::Gauge;
use quick_cache::Weighter;
use quick_cache::sync::Cache;

/// What a cache entry holds.
#[derive(Clone, Debug, Hash, PartialEq, Eq)]
pub enum CacheKey {
    /// A stored file of dataset `dataset` (index in the served list) at a decoded Zarr key.
    File {
        /// Dataset index.
        dataset: usize,
        /// Decoded key.
        key: String,
    },
    /// A brick of a batch, stored bytes (`raw == false`) or decoded samples (`raw == true`).
    Brick {
        /// Dataset index.
        dataset: usize,
        /// Level, channel and brick coordinates `z, y, x`.
        at: (u32, u32, [u64; 3]),
        /// Decoded samples rather than stored bytes.
        raw: bool,
    },
}

/// A cached answer: the bytes and, for files, their `ETag`. A brick entry with no bytes is
/// an empty brick.
#[derive(Clone, Debug)]
pub struct Cached {
    /// The bytes.
    pub bytes: Bytes,
    /// Entity tag of a file (empty for bricks).
    pub etag: Arc<str>,
}

#[derive(Clone)]
struct ByteWeight;

impl Weighter<CacheKey, Cached> for ByteWeight {
    fn weight(&self, key: &CacheKey, value: &Cached) -> u64 {
        let key_len = match key {
            CacheKey::File { key, .. } => key.len(),
            CacheKey::Brick { .. } => 32,
        };
        // Count the bookkeeping too, so many tiny entries cannot exceed the budget.
        (value.bytes.len() + value.etag.len() + key_len + 64) as u64
    }
}

/// The bounded cache, with its hit and miss counters.
pub struct ByteCache {
    inner: Option<Cache<CacheKey, Cached, ByteWeight>>,
    hits: Counter,
    misses: Counter,
    bytes: Gauge,
}

impl ByteCache {
    /// A cache holding at most `capacity` bytes (0 turns caching off), counting into the
    /// given metrics.
    pub fn new(capacity: u64, hits: Counter, misses: Counter, bytes: Gauge) -> Self {
        let inner = (capacity > 0).then(|| {
            // Estimate the entry count from a typical 32 KiB compressed brick.
            let items = (capacity / 32768).clamp(16, 1 << 20) as usize;
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
    pub fn get(&self, key: &CacheKey) -> Option<Cached> {
        let found = self.inner.as_ref().and_then(|c| c.get(key));
        if found.is_some() {
            self.hits.inc();
        } else {
            self.misses.inc();
        }
        found
    }

    /// Stores an entry (an entry larger than the whole budget is not kept).
    pub fn insert(&self, key: CacheKey, value: Cached) {
        if let Some(c) = &self.inner {
            c.insert(key, value);
            self.bytes.set(c.weight() as i64);
        }
    }

    /// Bytes held now.
    pub fn weight(&self) -> u64 {
        self.inner.as_ref().map_or(0, |c| c.weight())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn never_holds_more_than_its_budget() {
        let (hits, misses) = (Counter::default(), Counter::default());
        let cache = ByteCache::new(100_000, hits.clone(), misses.clone(), Gauge::default());
        for i in 0..1000 {
            cache.insert(
                CacheKey::File {
                    dataset: 0,
                    key: format!("c/{i}"),
                },
                Cached {
                    bytes: Bytes::from(vec![0u8; 1000]),
                    etag: "\"x\"".into(),
                },
            );
            assert!(cache.weight() <= 100_000, "{}", cache.weight());
        }
        let key = |i: usize| CacheKey::File {
            dataset: 0,
            key: format!("c/{i}"),
        };
        assert!(cache.get(&key(999)).is_some());
        assert!((0..1000).filter(|&i| cache.get(&key(i)).is_some()).count() < 100);
        assert_eq!(hits.get() + misses.get(), 1001);
        let off = ByteCache::new(0, hits, misses.clone(), Gauge::default());
        off.insert(key(1), cache.get(&key(999)).unwrap());
        assert!(off.get(&key(1)).is_none());
    }
}
