//! Blocking reads side by side. A store's one-time loads (the region metadata's arrays, read
//! through zarrs' synchronous API) wait on the network for every read over an object store, so
//! they run on threads of their own, a bounded number at once, instead of one after another.

use std::sync::atomic::{AtomicUsize, Ordering};

/// Most threads [`read_all`] reads on.
pub const READS_AT_ONCE: usize = 16;

/// `read(item)` for every item of `items`, on up to [`READS_AT_ONCE`] scoped threads, each
/// taking the next item not yet read; the results in the order of `items`.
///
/// # Panics
/// With a read's own panic, when one panics.
pub fn read_all<T: Sync, R: Send>(items: &[T], read: impl Fn(&T) -> R + Sync) -> Vec<R> {
    let next = AtomicUsize::new(0);
    let mut out: Vec<Option<R>> = std::iter::repeat_with(|| None).take(items.len()).collect();
    std::thread::scope(|scope| {
        let threads: Vec<_> = (0..items.len().min(READS_AT_ONCE))
            .map(|_| {
                scope.spawn(|| {
                    let mut done = Vec::new();
                    loop {
                        let i = next.fetch_add(1, Ordering::Relaxed);
                        let Some(item) = items.get(i) else {
                            return done;
                        };
                        done.push((i, read(item)));
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
    out.into_iter()
        .map(|r| r.expect("every item is read"))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_item_is_read_once_side_by_side_in_order() {
        let (now, most, calls) = (
            AtomicUsize::new(0),
            AtomicUsize::new(0),
            AtomicUsize::new(0),
        );
        let items: Vec<u64> = (0..40).collect();
        let out = read_all(&items, |&i| {
            calls.fetch_add(1, Ordering::SeqCst);
            most.fetch_max(now.fetch_add(1, Ordering::SeqCst) + 1, Ordering::SeqCst);
            std::thread::sleep(std::time::Duration::from_millis(20));
            now.fetch_sub(1, Ordering::SeqCst);
            i * 3
        });
        assert_eq!(out, (0..40).map(|i| i * 3).collect::<Vec<_>>());
        assert_eq!(calls.load(Ordering::SeqCst), 40);
        // 16 threads, each holding its read 20 ms: they overlap.
        assert_eq!(most.load(Ordering::SeqCst), READS_AT_ONCE);
        assert_eq!(read_all(&[] as &[u8], |_| 1), Vec::<i32>::new());
        let panicked = std::panic::catch_unwind(|| read_all(&[1, 2], |&i| assert_ne!(i, 2)));
        assert!(panicked.is_err());
    }
}
