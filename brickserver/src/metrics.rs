//! Server metrics in the Prometheus (OpenMetrics) text format: requests by status class,
//! bytes sent, a latency histogram, cache hits and misses (the hit rate is
//! `hits / (hits + misses)`), cached bytes, and open and refused connections.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use axum::body::{Body, HttpBody};
use axum::extract::{Request, State};
use axum::http::{Response, StatusCode, header};
use axum::middleware::Next;
use prometheus_client::encoding::text::encode;
use prometheus_client::encoding::{EncodeLabelSet, EncodeMetric, MetricEncoder, NoLabelSet};
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::{MetricType, TypedMetric};
use prometheus_client::registry::Registry;

/// The upper bounds of the request duration histogram's buckets, in seconds (and `+Inf`).
const LATENCY_BOUNDS: [f64; 12] = [
    0.0001, 0.00025, 0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 1.0,
];

/// The request duration histogram: every answer is recorded in it, from every thread that
/// serves connections, so it counts with atomic adds, not under a lock (as
/// `prometheus_client`'s `Histogram` does, one lock for all threads); it is written as a
/// classic Prometheus histogram.
#[derive(Clone, Debug, Default)]
struct LatencyHistogram(Arc<LatencyCounts>);

/// The counts of a [`LatencyHistogram`].
#[derive(Debug, Default)]
struct LatencyCounts {
    /// Observations by bucket: one per bound of [`LATENCY_BOUNDS`], then `+Inf`.
    buckets: [AtomicU64; LATENCY_BOUNDS.len() + 1],
    /// The sum of the observations, in nanoseconds.
    sum_nanos: AtomicU64,
}

impl LatencyHistogram {
    /// Records one request's duration.
    fn observe(&self, took: Duration) {
        let seconds = took.as_secs_f64();
        let bucket = LATENCY_BOUNDS
            .iter()
            .position(|bound| seconds <= *bound)
            .unwrap_or(LATENCY_BOUNDS.len());
        self.0.buckets[bucket].fetch_add(1, Ordering::Relaxed);
        let nanos = u64::try_from(took.as_nanos()).unwrap_or(u64::MAX);
        self.0.sum_nanos.fetch_add(nanos, Ordering::Relaxed);
    }
}

impl TypedMetric for LatencyHistogram {
    const TYPE: MetricType = MetricType::Histogram;
}

impl EncodeMetric for LatencyHistogram {
    fn encode(&self, mut encoder: MetricEncoder) -> std::fmt::Result {
        let bounds = LATENCY_BOUNDS.iter().copied().chain([f64::INFINITY]);
        let counts = self.0.buckets.iter().map(|n| n.load(Ordering::Relaxed));
        let buckets: Vec<(f64, u64)> = bounds.zip(counts).collect();
        // The count is the buckets' sum, so that the two agree in every scrape.
        let count = buckets.iter().map(|(_, n)| n).sum();
        let sum = self.0.sum_nanos.load(Ordering::Relaxed) as f64 / 1e9;
        encoder.encode_histogram::<NoLabelSet>(sum, count, &buckets, None)
    }

    fn metric_type(&self) -> MetricType {
        Self::TYPE
    }
}

/// Label of a request counter: the response's status class (`2xx`, `3xx`, `4xx`, `5xx`).
#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
pub(crate) struct StatusClass {
    /// `2xx`, `3xx`, `4xx` or `5xx`.
    pub class: String,
}

/// The server's metrics and their registry.
pub struct Metrics {
    registry: Registry,
    bytes: Counter,
    latency: LatencyHistogram,
    /// The request counters of classes 1xx..5xx, resolved once (no label lookup per request).
    by_class: [Counter; 5],
    /// Cache lookups that found their entry.
    pub cache_hits: Counter,
    /// Cache lookups that did not.
    pub cache_misses: Counter,
    /// Bytes held by the cache.
    pub cache_bytes: Gauge,
    /// Connections open now.
    pub connections: Gauge,
    /// Connections refused (503) because the connection limit was reached.
    pub connections_refused: Counter,
    /// Chunks of folder stores read into the page cache before they were sent (the page cache
    /// did not hold all of them).
    pub chunks_read_from_disk: Counter,
}

impl Default for Metrics {
    fn default() -> Self {
        let mut registry = Registry::default();
        let requests = Family::<StatusClass, Counter>::default();
        let bytes = Counter::default();
        let latency = LatencyHistogram::default();
        registry.register(
            "brickserver_requests",
            "Requests answered, by status class",
            requests.clone(),
        );
        registry.register(
            "brickserver_response_bytes",
            "Response body bytes sent",
            bytes.clone(),
        );
        registry.register(
            "brickserver_request_duration_seconds",
            "Time from request to response headers",
            latency.clone(),
        );
        let (cache_hits, cache_misses) = (Counter::default(), Counter::default());
        let (cache_bytes, connections) = (Gauge::default(), Gauge::default());
        let (connections_refused, chunks_read_from_disk) = (Counter::default(), Counter::default());
        registry.register(
            "brickserver_cache_hits",
            "Cache lookups that found their entry",
            cache_hits.clone(),
        );
        registry.register(
            "brickserver_cache_misses",
            "Cache lookups that did not find their entry",
            cache_misses.clone(),
        );
        registry.register(
            "brickserver_cache_bytes",
            "Bytes held by the memory cache",
            cache_bytes.clone(),
        );
        registry.register(
            "brickserver_connections",
            "Connections open now",
            connections.clone(),
        );
        registry.register(
            "brickserver_connections_refused",
            "Connections refused because the connection limit was reached",
            connections_refused.clone(),
        );
        registry.register(
            "brickserver_chunks_read_from_disk",
            "Chunks of folder stores read into the page cache before they were sent",
            chunks_read_from_disk.clone(),
        );
        let by_class = std::array::from_fn(|i| {
            requests
                .get_or_create(&StatusClass {
                    class: format!("{}xx", i + 1),
                })
                .clone()
        });
        Self {
            registry,
            bytes,
            latency,
            by_class,
            cache_hits,
            cache_misses,
            cache_bytes,
            connections,
            connections_refused,
            chunks_read_from_disk,
        }
    }
}

impl Metrics {
    /// Records an answer with `status` and `body_bytes` body bytes (`None`: no body sent)
    /// to a request that arrived at `started`.
    pub(crate) fn record(&self, status: StatusCode, body_bytes: Option<u64>, started: Instant) {
        self.latency.observe(started.elapsed());
        let class = (status.as_u16() / 100).clamp(1, 5) as usize - 1;
        self.by_class[class].inc();
        if let Some(len) = body_bytes {
            self.bytes.inc_by(len);
        }
    }

    /// The metrics as OpenMetrics text.
    pub(crate) fn render(&self) -> String {
        let mut out = String::new();
        encode(&mut out, &self.registry).expect("writing to a String cannot fail");
        out
    }
}

/// Middleware recording every request in `metrics`.
pub(crate) async fn track(
    State(metrics): State<Arc<Metrics>>,
    request: Request,
    next: Next,
) -> Response<Body> {
    let started = Instant::now();
    let head = request.method() == axum::http::Method::HEAD;
    let response = next.run(request).await;
    let announced = response
        .headers()
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    // HEAD answers announce a length but send no body.
    let sent = announced
        .or_else(|| response.body().size_hint().exact())
        .filter(|_| !head);
    metrics.record(response.status(), sent, started);
    response
}

#[cfg(test)]
mod tests {
    use prometheus_client::metrics::histogram::Histogram;

    use super::*;

    /// `metric`'s text under the name `latency`.
    fn text_of(metric: impl prometheus_client::registry::Metric) -> String {
        let mut registry = Registry::default();
        registry.register("latency", "Durations", metric);
        let mut out = String::new();
        encode(&mut out, &registry).unwrap();
        out
    }

    #[test]
    fn the_latency_histogram_is_written_as_prometheus_client_writes_its_own() {
        let took = [
            Duration::from_micros(60),
            Duration::from_micros(100),
            Duration::from_millis(2),
            Duration::from_millis(250),
            Duration::from_secs(2),
        ];
        let ours = LatencyHistogram::default();
        let theirs = Histogram::new(LATENCY_BOUNDS);
        for t in took {
            ours.observe(t);
            theirs.observe(t.as_secs_f64());
        }
        let ours = text_of(ours);
        // The same lines but for the sum, which theirs adds up in floating point.
        let without_sum = |text: &str| {
            text.lines()
                .filter(|l| !l.starts_with("latency_sum"))
                .map(str::to_string)
                .collect::<Vec<_>>()
        };
        assert_eq!(without_sum(&ours), without_sum(&text_of(theirs)));
        assert!(ours.contains("latency_sum 2.25216\n"), "{ours}");
        assert!(ours.contains("latency_count 5\n"), "{ours}");
        assert!(ours.contains("latency_bucket{le=\"0.0001\"} 2\n"), "{ours}");
        assert!(ours.contains("latency_bucket{le=\"0.25\"} 4\n"), "{ours}");
        assert!(ours.contains("latency_bucket{le=\"+Inf\"} 5\n"), "{ours}");
    }
}
