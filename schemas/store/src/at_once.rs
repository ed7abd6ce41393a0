//! Blocking reads side by side. A store's one-time loads (its levels' documents, the region
//! metadata's arrays, read through zarrs' synchronous API) wait on the network for every read
//! over an object store, so they run on threads of their own, a bounded number at once,
//! instead of one after another.

use std::sync::atomic::{AtomicUsize, Ordering};

/// Most threads [`try_read_all`] reads on.
pub const READS_AT_ONCE: usize = 16;

/// `read(item)` for the items of `items`, on up to [`READS_AT_ONCE`] scoped threads, each
/// taking the next item not yet read, and the results in the order of `items` up to the first
/// error: every item before it has been read, and no item after the first that failed is
/// started (a failing store is not asked again for the rest, each with its retries). Callers
/// check the results in order, as a loop reading one after another would.
///
/// # Panics
/// With a read's own panic, when one panics.
pub fn try_read_all<T, R, E>(
    items: &[T],
    read: impl Fn(&T) -> Result<R, E> + Sync,
) -> Vec<Result<R, E>>
where
    T: Sync,
    R: Send,
    E: Send,
{
    let next = AtomicUsize::new(0);
    // The lowest index that failed; items past it are not started.
    let failed = AtomicUsize::new(usize::MAX);
    let mut out: Vec<Option<Result<R, E>>> =
        std::iter::repeat_with(|| None).take(items.len()).collect();
    std::thread::scope(|scope| {
        let threads: Vec<_> = (0..items.len().min(READS_AT_ONCE))
            .map(|_| {
                scope.spawn(|| {
                    let mut done = Vec::new();
                    loop {
                        let i = next.fetch_add(1, Ordering::SeqCst);
                        let Some(item) = items.get(i) else {
                            return done;
                        };
                        if i > failed.load(Ordering::SeqCst) {
                            return done;
                        }
                        let result = read(item);
                        if result.is_err() {
                            failed.fetch_min(i, Ordering::SeqCst);
                        }
                        done.push((i, result));
                    }
                })
            })
            .collect();
        for thread in threads {
            match thread.join() {
                Ok(done) => done.into_iter().for_each(|(i, r)| out[i] = Some(r)),
                Err(panic) => std::panic::resume_unwind(panic),
            }
        }
    });
    let mut results = Vec::with_capacity(items.len());
    for result in out {
        let result = result.expect("every item before the first error is read");
        let stop = result.is_err();
        results.push(result);
        if stop {
            break;
        }
    }
    results
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::{Duration, Instant};

    #[test]
    fn every_item_is_read_once_side_by_side_in_order() {
        let (now, most, calls) = (
            AtomicUsize::new(0),
            AtomicUsize::new(0),
            AtomicUsize::new(0),
        );
        let items: Vec<u64> = (0..40).collect();
        let out = try_read_all(&items, |&i| {
            calls.fetch_add(1, Ordering::SeqCst);
            most.fetch_max(now.fetch_add(1, Ordering::SeqCst) + 1, Ordering::SeqCst);
            // The first reads wait for one another: all threads read at once.
            let deadline = Instant::now() + Duration::from_secs(10);
            while most.load(Ordering::SeqCst) < READS_AT_ONCE && Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(1));
            }
            now.fetch_sub(1, Ordering::SeqCst);
            Ok::<_, ()>(i * 3)
        });
        assert_eq!(out, (0..40).map(|i| Ok(i * 3)).collect::<Vec<_>>());
        assert_eq!(calls.load(Ordering::SeqCst), 40);
        assert_eq!(most.load(Ordering::SeqCst), READS_AT_ONCE);
        assert_eq!(try_read_all(&[] as &[u8], |_| Ok::<u8, ()>(1)), Vec::new());
    }

    #[test]
    fn reading_stops_after_the_first_error_in_order() {
        let (calls, five_failed) = (AtomicUsize::new(0), AtomicUsize::new(0));
        let items: Vec<u64> = (0..200).collect();
        let out = try_read_all(&items, |&i| {
            calls.fetch_add(1, Ordering::SeqCst);
            if i == 5 || i == 9 {
                if i == 5 {
                    five_failed.store(1, Ordering::SeqCst);
                }
                return Err(format!("item {i} failed"));
            }
            // Later reads end well after item 5 has failed, so no thread is free to start
            // another before the failure is known.
            if i > 5 {
                while five_failed.load(Ordering::SeqCst) == 0 {
                    std::thread::sleep(Duration::from_millis(1));
                }
                std::thread::sleep(Duration::from_millis(200));
            }
            Ok(i)
        });
        // Items 0 to 4, then item 5's error: the one a loop in order would meet first.
        let mut expected: Vec<Result<u64, String>> = (0..5).map(Ok).collect();
        expected.push(Err("item 5 failed".to_string()));
        assert_eq!(out, expected);
        // Items past a failure are not started: items 0 to 5 and at most the other threads'
        // reads in flight then, not the 200.
        assert!(calls.load(Ordering::SeqCst) <= 5 + READS_AT_ONCE);
        let panicked = std::panic::catch_unwind(|| {
            try_read_all(&[1, 2], |&i| {
                assert!(i != 2, "item 2 is cursed");
                Ok::<_, ()>(i)
            })
        });
        let message = panicked.unwrap_err();
        assert_eq!(message.downcast_ref::<&str>(), Some(&"item 2 is cursed"));
    }
}
