//! The request rate bound: a token bucket holding a second's worth of requests.

use std::time::Instant;

/// A token bucket: `rate` tokens a second, at most `max(rate, 1)` kept, one per request.
#[derive(Debug)]
pub(crate) struct Bucket {
    rate: f64,
    tokens: f64,
    last: Option<Instant>,
}

impl Bucket {
    /// A full bucket of `rate` requests a second.
    pub(crate) fn new(rate: f64) -> Self {
        Self {
            rate,
            tokens: rate.max(1.0),
            last: None,
        }
    }

    /// Takes a token at `now`: whether the request is within the rate.
    pub(crate) fn take(&mut self, now: Instant) -> bool {
        if let Some(last) = self.last {
            let elapsed = now.saturating_duration_since(last).as_secs_f64();
            self.tokens = (self.tokens + elapsed * self.rate).min(self.rate.max(1.0));
        }
        self.last = Some(now);
        if self.tokens >= 1.0 {
            self.tokens -= 1.0;
            true
        } else {
            false
        }
    }

    /// Whole seconds until the next token, at least 1: the `Retry-After` of a request
    /// refused by [`Bucket::take`].
    pub(crate) fn retry_after_s(&self) -> u64 {
        // Finite and at most 1 / rate for a positive rate; the cast saturates.
        let seconds = ((1.0 - self.tokens) / self.rate).ceil() as u64;
        seconds.max(1)
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;

    #[test]
    fn a_burst_of_the_rate_then_one_per_period() {
        let t0 = Instant::now();
        let mut bucket = Bucket::new(4.0);
        assert_eq!(
            (0..5).map(|_| bucket.take(t0)).collect::<Vec<_>>(),
            [true, true, true, true, false]
        );
        assert!(!bucket.take(t0 + Duration::from_millis(200)));
        assert!(bucket.take(t0 + Duration::from_millis(260)));
        assert!(!bucket.take(t0 + Duration::from_millis(270)));
        // A long pause refills the bucket only to its capacity.
        let later = t0 + Duration::from_mins(1);
        assert_eq!((0..5).filter(|_| bucket.take(later)).count(), 4);
        // Under one a second: one request, then one per 1/rate seconds.
        let mut slow = Bucket::new(0.5);
        assert!(slow.take(t0) && !slow.take(t0 + Duration::from_secs(1)));
        // Half a token left: one more second.
        assert_eq!(slow.retry_after_s(), 1);
        assert!(slow.take(t0 + Duration::from_secs(2)));
        assert_eq!(slow.retry_after_s(), 2);
        assert!(!bucket.take(later));
        assert_eq!(bucket.retry_after_s(), 1);
    }
}
