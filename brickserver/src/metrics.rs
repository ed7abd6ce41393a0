//! Server metrics in the Prometheus (OpenMetrics) text format: requests by status class,
//! bytes sent, a latency histogram, cache hits and misses (the hit rate is
//! `hits / (hits + misses)`), cached bytes, and open and refused connections.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use axum::body::{Body, HttpBody};
use axum::extract::{Request, State};
use axum::http::{Response, StatusCode, header};
use axum::middleware::Next;
use prometheus_client::encoding::text::encode;
use prometheus_client::encoding::{EncodeLabelSet, EncodeMetric, MetricEncoder, NoLabelSet};
use prometheus_client::metrics::MetricType;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::registry::Registry;

/// The upper bounds of the request duration histogram's buckets, in seconds (and `+Inf`).
const LATENCY_BOUNDS: [f64; 12] = [
    0.0001, 0.00025, 0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 1.0,
];

/// How many slots the per-request counts are spread over. Each thread that records answers
/// adds to a slot of its own (threads past this many share them), so that recording an answer
/// moves no cache line between the cores serving connections, as nginx's workers share none.
const SLOTS: usize = 16;

/// One thread's share of the counts every answer adds to, alone on its cache lines.
#[derive(Debug, Default)]
#[repr(align(128))]
struct RequestSlot {
    /// Answers by duration: one per bound of [`LATENCY_BOUNDS`], then `+Inf`.
    latency: [AtomicU64; LATENCY_BOUNDS.len() + 1],
    /// The sum of the answers' durations, in nanoseconds.
    latency_sum_nanos: AtomicU64,
    /// Answers by status class, `1xx` to `5xx`.
    by_class: [AtomicU64; 5],
    /// Body bytes sent.
    bytes: AtomicU64,
}

/// The counts every answer adds to (duration, status class, body bytes), one
/// [`RequestSlot`] per recording thread, added up when they are written. Three views of them
/// are registered: [`LatencyHistogram`], [`RequestsByClass`] and [`ResponseBytes`].
#[derive(Clone, Debug, Default)]
struct RequestCounts(Arc<[RequestSlot; SLOTS]>);

impl RequestCounts {
    /// The calling thread's slot.
    fn slot(&self) -> &RequestSlot {
        static NEXT: AtomicUsize = AtomicUsize::new(0);
        thread_local! {
            static SLOT: usize = NEXT.fetch_add(1, Ordering::Relaxed) % SLOTS;
        }
        &self.0[SLOT.with(|slot| *slot)]
    }

    /// Records one answer: its duration, its status class (`0` for `1xx` to `4` for `5xx`)
    /// and the body bytes it sent.
    fn record(&self, took: Duration, class: usize, body_bytes: Option<u64>) {
        let slot = self.slot();
        let seconds = took.as_secs_f64();
        let bucket = LATENCY_BOUNDS
            .iter()
            .position(|bound| seconds <= *bound)
            .unwrap_or(LATENCY_BOUNDS.len());
        slot.latency[bucket].fetch_add(1, Ordering::Relaxed);
        let nanos = u64::try_from(took.as_nanos()).unwrap_or(u64::MAX);
        slot.latency_sum_nanos.fetch_add(nanos, Ordering::Relaxed);
        slot.by_class[class].fetch_add(1, Ordering::Relaxed);
        if let Some(len) = body_bytes {
            slot.bytes.fetch_add(len, Ordering::Relaxed);
        }
    }

    /// The sum over every slot of the count `of` picks.
    fn total(&self, of: impl Fn(&RequestSlot) -> &AtomicU64) -> u64 {
        self.0
            .iter()
            .map(|slot| of(slot).load(Ordering::Relaxed))
            .fold(0, u64::wrapping_add)
    }
}

/// The request duration histogram, written as a classic Prometheus histogram.
#[derive(Clone, Debug, Default)]
struct LatencyHistogram(RequestCounts);

impl EncodeMetric for LatencyHistogram {
    fn encode(&self, mut encoder: MetricEncoder) -> std::fmt::Result {
        let bounds = LATENCY_BOUNDS.iter().copied().chain([f64::INFINITY]);
        let counts = (0..=LATENCY_BOUNDS.len()).map(|i| self.0.total(|slot| &slot.latency[i]));
        let buckets: Vec<(f64, u64)> = bounds.zip(counts).collect();
        // The count is the buckets' sum, so that the two agree in every scrape.
        let count = buckets.iter().map(|(_, n)| n).sum();
        let sum = self.0.total(|slot| &slot.latency_sum_nanos) as f64 / 1e9;
        encoder.encode_histogram::<NoLabelSet>(sum, count, &buckets, None)
    }

    fn metric_type(&self) -> MetricType {
        MetricType::Histogram
    }
}

/// The requests answered, a counter per status class (`1xx` to `5xx`, all five written).
#[derive(Clone, Debug, Default)]
struct RequestsByClass(RequestCounts);

impl EncodeMetric for RequestsByClass {
    fn encode(&self, mut encoder: MetricEncoder) -> std::fmt::Result {
        for class in 0..5 {
            let label = StatusClass {
                class: format!("{}xx", class + 1),
            };
            let total = self.0.total(|slot| &slot.by_class[class]);
            encoder
                .encode_family(&label)?
                .encode_counter::<NoLabelSet, _, u64>(&total, None)?;
        }
        Ok(())
    }

    fn metric_type(&self) -> MetricType {
        MetricType::Counter
    }
}

/// The response body bytes sent, a counter.
#[derive(Clone, Debug, Default)]
struct ResponseBytes(RequestCounts);

impl EncodeMetric for ResponseBytes {
    fn encode(&self, mut encoder: MetricEncoder) -> std::fmt::Result {
        let total = self.0.total(|slot| &slot.bytes);
        encoder.encode_counter::<NoLabelSet, _, u64>(&total, None)
    }

    fn metric_type(&self) -> MetricType {
        MetricType::Counter
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
    /// What every answer adds to: requests by class, bytes sent and durations.
    requests: RequestCounts,
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
        let requests = RequestCounts::default();
        registry.register(
            "brickserver_requests",
            "Requests answered, by status class",
            RequestsByClass(requests.clone()),
        );
        registry.register(
            "brickserver_response_bytes",
            "Response body bytes sent",
            ResponseBytes(requests.clone()),
        );
        registry.register(
            "brickserver_request_duration_seconds",
            "Time from request to response headers",
            LatencyHistogram(requests.clone()),
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
        Self {
            registry,
            requests,
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
    /// to a request that arrived at `started` and was answered at `ended`.
    pub(crate) fn record(
        &self,
        status: StatusCode,
        body_bytes: Option<u64>,
        started: Instant,
        ended: Instant,
    ) {
        let class = (status.as_u16() / 100).clamp(1, 5) as usize - 1;
        self.requests
            .record(ended.saturating_duration_since(started), class, body_bytes);
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
    metrics.record(response.status(), sent, started, Instant::now());
    response
}

#[cfg(test)]
mod tests {
    use prometheus_client::metrics::family::Family;
    use prometheus_client::metrics::histogram::Histogram;

    use super::*;

    /// `metric`'s text under the name `name`.
    fn text_of(name: &str, metric: impl prometheus_client::registry::Metric) -> String {
        let mut registry = Registry::default();
        registry.register(name, "Help", metric);
        let mut out = String::new();
        encode(&mut out, &registry).unwrap();
        out
    }

    /// `text`'s lines, sorted.
    fn sorted_lines(text: &str) -> Vec<&str> {
        let mut lines: Vec<&str> = text.lines().collect();
        lines.sort_unstable();
        lines
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
        let ours = RequestCounts::default();
        let theirs = Histogram::new(LATENCY_BOUNDS);
        for t in took {
            ours.record(t, 1, None);
            theirs.observe(t.as_secs_f64());
        }
        let ours = text_of("latency", LatencyHistogram(ours));
        // The same lines but for the sum, which theirs adds up in floating point.
        let without_sum = |text: &str| {
            text.lines()
                .filter(|l| !l.starts_with("latency_sum"))
                .map(str::to_string)
                .collect::<Vec<_>>()
        };
        assert_eq!(without_sum(&ours), without_sum(&text_of("latency", theirs)));
        assert!(ours.contains("latency_sum 2.25216\n"), "{ours}");
        assert!(ours.contains("latency_count 5\n"), "{ours}");
        assert!(ours.contains("latency_bucket{le=\"0.0001\"} 2\n"), "{ours}");
        assert!(ours.contains("latency_bucket{le=\"0.25\"} 4\n"), "{ours}");
        assert!(ours.contains("latency_bucket{le=\"+Inf\"} 5\n"), "{ours}");
    }

    #[test]
    fn requests_and_bytes_are_written_as_prometheus_client_writes_its_counters() {
        let ours = RequestCounts::default();
        let theirs = Family::<StatusClass, Counter>::default();
        let bytes = Counter::<u64>::default();
        let answers = [
            (0, None),
            (1, Some(7)),
            (1, Some(0)),
            (3, Some(12)),
            (4, None),
        ];
        for (class, sent) in answers {
            ours.record(Duration::from_micros(50), class, sent);
            let label = StatusClass {
                class: format!("{}xx", class + 1),
            };
            theirs.get_or_create(&label).inc();
            bytes.inc_by(sent.unwrap_or(0));
        }
        // Theirs writes only the classes it has seen, in no fixed order.
        theirs
            .get_or_create(&StatusClass {
                class: "3xx".into(),
            })
            .inc_by(0);
        let requests = text_of("requests", RequestsByClass(ours.clone()));
        assert_eq!(
            sorted_lines(&requests),
            sorted_lines(&text_of("requests", theirs))
        );
        assert!(
            requests.contains(
                "requests_total{class=\"1xx\"} 1\nrequests_total{class=\"2xx\"} 2\n\
                 requests_total{class=\"3xx\"} 0\nrequests_total{class=\"4xx\"} 1\n\
                 requests_total{class=\"5xx\"} 1\n"
            ),
            "{requests}"
        );
        let sent = text_of("bytes", ResponseBytes(ours));
        assert_eq!(sent, text_of("bytes", bytes));
        assert!(sent.contains("bytes_total 19\n"), "{sent}");
    }

    #[test]
    fn answers_recorded_on_more_threads_than_slots_are_all_counted() {
        let counts = RequestCounts::default();
        let threads = SLOTS + 4;
        std::thread::scope(|scope| {
            for t in 0..threads {
                let counts = &counts;
                scope.spawn(move || {
                    for _ in 0..1000 {
                        counts.record(Duration::from_micros(10 + t as u64), 1, Some(3));
                    }
                });
            }
        });
        let answers = 1000 * threads as u64;
        assert_eq!(counts.total(|slot| &slot.by_class[1]), answers);
        assert_eq!(counts.total(|slot| &slot.bytes), 3 * answers);
        assert_eq!(counts.total(|slot| &slot.latency[0]), answers);
        // 1000 answers of 10 + t microseconds from each thread t.
        let nanos: u64 = (0..threads as u64).map(|t| 1000 * (10 + t) * 1000).sum();
        assert_eq!(counts.total(|slot| &slot.latency_sum_nanos), nanos);
        let text = text_of("latency", LatencyHistogram(counts));
        assert!(
            text.contains(&format!("latency_count {answers}\n")),
            "{text}"
        );
    }
}
