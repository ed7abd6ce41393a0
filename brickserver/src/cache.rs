//! A bounded in-memory cache of bricks served in batches: decoded samples, or stored bytes cut
//! out of shards. Its size never exceeds the configured byte budget (`--cache-bytes`); entries
//! are evicted by quick_cache's CLOCK-PRO policy. Hits and misses are counted in the metrics.

use axum::body::Bytes;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::gauge::Gauge;
use quick_cache::Weighter;
use quick_cache::sync::Cache;

/// A brick of a batch: dataset (index in the served list), level, channel, brick
/// coordinates `z, y, x`, and whether it holds decoded samples (`raw`) or stored bytes.
#[derive(Clone, Debug, Hash, PartialEq, Eq)]
pub struct CacheKey {
    /// Dataset index.
    pub dataset: usize,
    /// Level, channel and brick coordinates `z, y, x`.
    pub at: (u32, u32, [u64; 3]),
    /// Decoded samples rather than stored bytes.
    pub raw: bool,
}

#[derive(Clone)]
struct ByteWeight;

impl Weighter<CacheKey, Bytes> for ByteWeight {
    fn weight(&self, _key: &CacheKey, value: &Bytes) -> u64 {
        // Count the bookkeeping too, so many empty bricks cannot exceed the budget.
        (value.len() + 96) as u64
    }
}

/// The bounded cache, with its hit and miss counters.
pub struct ByteCache {
    inner: Option<Cache<CacheKey, Bytes, ByteWeight>>,
    hits: Counter,
    misses: Counter,
    bytes: Gauge,
}

impl ByteCache {
    /// A cache holding at most `capacity` bytes (0 turns caching off), counting into the
    /// given metrics.
    pub fn new(capacity: u64, hits: Counter, misses: Counter, bytes: Gauge) -> Self {
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

    /// The cached bytes for `key` (empty for an empty brick), counting a hit or a miss.
    pub fn get(&self, key: &CacheKey) -> Option<Bytes> {
        let found = self.inner.as_ref().and_then(|c| c.get(key));
        if found.is_some() {
            self.hits.inc();
        } else {
            self.misses.inc();
        }
        found
    }

    /// Stores an entry (an entry larger than the whole budget is not kept).
    pub fn insert(&self, key: CacheKey, value: Bytes) {
        if let Some(c) = &self.inner {
            c.insert(key, value);
            self.bytes.set(c.weight() as i64);
        }
    }

    /// Bytes held now.
    pub fn weight(&self) -> u64 {
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
        let key = |i: u64| CacheKey {
            dataset: 0,
            at: (0, 0, [0, 0, i]),
            raw: true,
        };
        for i in 0..1000 {
            cache.insert(key(i), Bytes::from(vec![0u8; 1000]));
            assert!(cache.weight() <= 100_000, "{}", cache.weight());
        }
        assert!(cache.get(&key(999)).is_some());
        assert!((0..1000).filter(|&i| cache.get(&key(i)).is_some()).count() < 100);
        assert_eq!(hits.get() + misses.get(), 1001);
        let off = ByteCache::new(0, hits, misses.clone(), Gauge::default());
        off.insert(key(1), Bytes::from_static(b"x"));
        assert!(off.get(&key(1)).is_none());
    }
}
