//! Chunk files held open between requests, as nginx's `open_file_cache`: a chunk asked for
//! again is answered from its descriptor, without a path look-up, `openat2` or `close`. Before
//! its bytes are sent, one `statx` of the descriptor checks that the file still has a name and
//! the length and modification time it had when it was opened; a file deleted, renamed over or
//! changed in place is let go and its key opened again, so an answer's bytes are always those
//! of its `ETag` (a matching revalidation is answered `304` without that look, as nginx's is
//! within `open_file_cache_valid`). Whether the page cache holds the bytes to send is asked
//! once a request too (`cachestat`), except of a file it was seen to hold whole within the last
//! [`CACHED_FOR`]. The
//! files are shared by every thread that serves connections (one descriptor per chunk, where
//! nginx keeps one per worker); the least used are closed when the cache is full, and a sweep
//! every maximum age (the server's one minute) closes those opened longer ago than that, so the
//! files of a store deleted while nobody asks for them do not hold its disk space for long.

use std::fs::File;
use std::os::unix::fs::MetadataExt;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Weak, mpsc};
use std::time::{Duration, Instant};

use crate::page_cache;
use crate::responses::etag_of;

/// How long a file the page cache was seen to hold whole is taken as held still, without asking
/// again. Sending it touched its pages, and the page cache evicts the pages used least recently
/// first, so a file just sent is among the last to go. Asking is a system call a request
/// (`cachestat`): measured on 2 cores under wrk at 256 connections, about 4 % of the server's CPU
/// (0.7 µs a request). Were the pages dropped meanwhile after all, the answer's `sendfile`
/// reads them from the disk on the thread serving the connection, as nginx's always do.
pub(crate) const CACHED_FOR: Duration = Duration::from_secs(1);

/// A borrowed key of a `(dataset index, raw key)` cache: hashes and compares as the owned
/// `(usize, String)`, so a look-up allocates nothing.
#[derive(Hash)]
pub(crate) struct BorrowedKey<'a>(pub(crate) usize, pub(crate) &'a str);

impl quick_cache::Equivalent<(usize, String)> for BorrowedKey<'_> {
    fn equivalent(&self, key: &(usize, String)) -> bool {
        self.0 == key.0 && self.1 == key.1
    }
}

/// A chunk file, open, with what its answers need.
pub(crate) struct OpenFile {
    /// The file (read at explicit offsets only, so threads share it).
    pub(crate) file: File,
    /// Its length in bytes when it was opened.
    pub(crate) len: u64,
    /// Its `ETag` (quoted, [`etag_of`] its metadata when it was opened).
    pub(crate) etag: String,
    /// The dataset folder it was opened beneath ([`RootDir::identity`]): a file of a folder
    /// since replaced whole is not answered for the new one.
    ///
    /// [`RootDir::identity`]: crate::store_keys::RootDir::identity
    pub(crate) folder: (u64, u64),
    /// Its modification time when it was opened (seconds, nanoseconds).
    modified: (i64, i64),
    /// When it was opened.
    opened: Instant,
    /// When the page cache was last seen to hold the whole file: milliseconds after `opened`,
    /// plus one (0: not seen yet).
    seen_cached: AtomicU64,
}

impl OpenFile {
    /// `file`, opened now beneath the dataset folder `folder`, with its metadata `meta`.
    pub(crate) fn new(file: File, meta: &std::fs::Metadata, folder: (u64, u64)) -> Self {
        Self {
            file,
            len: meta.len(),
            etag: etag_of(meta),
            folder,
            modified: (meta.mtime(), meta.mtime_nsec()),
            opened: Instant::now(),
            seen_cached: AtomicU64::new(0),
        }
    }

    /// Whether the page cache holds bytes `start..end` of the file at `now`: yes without asking
    /// when it was seen to hold the whole file within the last [`CACHED_FOR`], else as
    /// [`page_cache::holds`] says.
    pub(crate) fn cached(&self, start: u64, end: u64, now: Instant) -> bool {
        let seen = self.seen_cached.load(Ordering::Relaxed);
        // A `now` taken before another thread's sighting counts as at it.
        let fresh =
            seen != 0 && u128::from(self.stamp(now).saturating_sub(seen)) < CACHED_FOR.as_millis();
        if fresh {
            return true;
        }
        let held = page_cache::holds(&self.file, start, end);
        if held {
            self.saw_cached(start, end, now);
        }
        held
    }

    /// Notes that the page cache held bytes `start..end` at `now` (remembered when they are the
    /// whole file).
    pub(crate) fn saw_cached(&self, start: u64, end: u64, now: Instant) {
        if start == 0 && end == self.len {
            self.seen_cached.store(self.stamp(now), Ordering::Relaxed);
        }
    }

    /// `now` as `seen_cached` holds it.
    fn stamp(&self, now: Instant) -> u64 {
        let ms = now.saturating_duration_since(self.opened).as_millis();
        u64::try_from(ms).unwrap_or(u64::MAX - 1) + 1
    }

    /// Whether the file still has a name and the length and modification time it had when it
    /// was opened (one `statx` of its descriptor).
    pub(crate) fn unchanged(&self) -> bool {
        self.file.metadata().is_ok_and(|meta| {
            meta.nlink() > 0
                && meta.len() == self.len
                && (meta.mtime(), meta.mtime_nsec()) == self.modified
        })
    }
}

/// The chunk files held open, by dataset index and raw key.
pub(crate) struct OpenFiles {
    files: quick_cache::sync::Cache<(usize, String), Arc<OpenFile>>,
    /// How long after it was opened a file is let go.
    max_age: Duration,
    /// The sweep's thread, stopped and joined when the cache is dropped (`None` without one).
    sweeper: Option<Sweeper>,
}

/// The thread that closes the files held too long, and the channel whose closing stops it.
struct Sweeper {
    stop: mpsc::Sender<()>,
    thread: std::thread::JoinHandle<()>,
}

impl Sweeper {
    /// A thread that, every `max_age`, closes the files the cache `open` has held too long;
    /// `None` (with a warning) when no thread can be started.
    fn start(open: Weak<OpenFiles>, max_age: Duration) -> Option<Self> {
        let (stop, stopped) = mpsc::channel();
        let thread = std::thread::Builder::new()
            .name("open-files".into())
            .spawn(move || sweep(&open, &stopped, max_age));
        match thread {
            Ok(thread) => Some(Self { stop, thread }),
            Err(e) => {
                tracing::warn!(
                    "no thread to close files held too long ({e}): they close when evicted"
                );
                None
            }
        }
    }
}

impl Drop for OpenFiles {
    /// Stops the sweep and waits for its thread, so that nothing is left running (unless the
    /// sweep itself held the last reference).
    fn drop(&mut self) {
        if let Some(Sweeper { stop, thread }) = self.sweeper.take() {
            drop(stop);
            if thread.thread().id() != std::thread::current().id() {
                let _ = thread.join();
            }
        }
    }
}

impl OpenFiles {
    /// Up to `asked` files, but at most a quarter of this process's open-file limit (the rest
    /// is for connections and the store's other reads), each held for at most `max_age`;
    /// `None` when that is none (every request opens its file). A thread closes the files held
    /// too long, every `max_age`, until the cache is dropped.
    pub(crate) fn new(asked: usize, max_age: Duration) -> Option<Arc<Self>> {
        let capacity = within_file_limit(asked, file_limit());
        (capacity > 0).then(|| {
            Arc::new_cyclic(|weak| {
                let mut open = Self::unswept(capacity, max_age);
                open.sweeper = Sweeper::start(weak.clone(), max_age);
                open
            })
        })
    }

    /// Up to `capacity` files, each held for at most `max_age`, without the sweep.
    fn unswept(capacity: usize, max_age: Duration) -> Self {
        Self {
            files: quick_cache::sync::Cache::new(capacity),
            max_age,
            sweeper: None,
        }
    }

    /// Chunk `raw_key` of dataset `index`, if it is held open and was not held too long at
    /// `now` (one held too long is let go). Whether it is unchanged is
    /// [`OpenFile::unchanged`]'s to say.
    pub(crate) fn get(&self, index: usize, raw_key: &str, now: Instant) -> Option<Arc<OpenFile>> {
        let open = self.files.get(&BorrowedKey(index, raw_key))?;
        if now.saturating_duration_since(open.opened) < self.max_age {
            return Some(open);
        }
        self.let_go(index, raw_key, &open);
        None
    }

    /// Lets go of `open`, chunk `raw_key` of dataset `index` (unless another file has taken
    /// its place), so that the next request opens the key again.
    pub(crate) fn let_go(&self, index: usize, raw_key: &str, open: &Arc<OpenFile>) {
        // The removed file is returned, so it closes (if this was its last holder) after the
        // cache's lock is released.
        self.files
            .remove_if(&BorrowedKey(index, raw_key), |held| Arc::ptr_eq(held, open));
    }

    /// Lets go of every file held of dataset `index` (its folder was replaced).
    pub(crate) fn let_go_dataset(&self, index: usize) {
        self.let_go_where(|(held, _), _| *held == index);
    }

    /// Holds `open`, chunk `raw_key` of dataset `index`, open (closing the least used file
    /// when the cache is full, or the one it replaces once no answer is sending from it).
    pub(crate) fn insert(&self, index: usize, raw_key: &str, open: Arc<OpenFile>) {
        self.files.insert((index, raw_key.to_string()), open);
    }

    /// Closes every file held for its maximum age or longer.
    fn close_stale(&self) {
        self.let_go_where(|_, open| open.opened.elapsed() >= self.max_age);
    }

    /// Lets go of every file held that `which` picks, by its key and file; they close after
    /// the cache's locks are released, as closing the last descriptor of a deleted file frees
    /// its blocks.
    fn let_go_where(&self, which: impl Fn(&(usize, String), &OpenFile) -> bool) {
        let picked: Vec<_> = self
            .files
            .iter()
            .filter(|(key, open)| which(key, open))
            .collect();
        for ((index, key), open) in picked {
            self.let_go(index, &key, &open);
        }
    }
}

/// Every `max_age`, closes the files the cache `open` has held too long, until the cache is
/// dropped (which closes `stopped`'s channel).
fn sweep(open: &Weak<OpenFiles>, stopped: &mpsc::Receiver<()>, max_age: Duration) {
    while let Err(mpsc::RecvTimeoutError::Timeout) = stopped.recv_timeout(max_age) {
        match open.upgrade() {
            Some(open) => open.close_stale(),
            None => return,
        }
    }
}

/// This process's open-file limit (its soft `RLIMIT_NOFILE`), if known.
fn file_limit() -> Option<u64> {
    let mut limit = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit only writes the struct passed.
    (unsafe { libc::getrlimit(libc::RLIMIT_NOFILE, &raw mut limit) } == 0).then_some(limit.rlim_cur)
}

/// `asked` files, lowered to a quarter of the open-file `limit` (with a warning).
fn within_file_limit(asked: usize, limit: Option<u64>) -> usize {
    let Some(limit) = limit else {
        return asked;
    };
    let most = usize::try_from(limit / 4).unwrap_or(usize::MAX);
    if asked > most {
        tracing::warn!(
            "--open-files {asked} lowered to {most}, a quarter of the open-file limit ({limit})"
        );
    }
    asked.min(most)
}

#[cfg(test)]
mod tests {
    use std::io::Write;

    use super::*;
    use crate::page_cache::tests::drop_pages;

    /// A held file of `bytes`, opened `age` ago.
    fn held(bytes: &[u8], age: Duration) -> (tempfile::NamedTempFile, Arc<OpenFile>) {
        let mut named = tempfile::NamedTempFile::new().unwrap();
        named.write_all(bytes).unwrap();
        let file = named.reopen().unwrap();
        let meta = file.metadata().unwrap();
        let mut open = OpenFile::new(file, &meta, (0, 0));
        open.opened = Instant::now().checked_sub(age).unwrap();
        (named, Arc::new(open))
    }

    #[test]
    fn files_are_found_by_dataset_and_key_while_young_and_unchanged() {
        let files = OpenFiles::unswept(16, Duration::from_mins(1));
        let (_a, a) = held(b"abcde", Duration::ZERO);
        let (_b, b) = held(b"abcdef", Duration::ZERO);
        let (_c, old) = held(b"abc", Duration::from_mins(1));
        files.insert(3, "0/c/0/1/2/3", a);
        files.insert(2, "0/c/0/1/2/3", b);
        files.insert(3, "0/c/0/1/2/5", old);
        assert_eq!(
            files.get(3, "0/c/0/1/2/3", Instant::now()).map(|f| f.len),
            Some(5)
        );
        assert_eq!(
            files.get(2, "0/c/0/1/2/3", Instant::now()).map(|f| f.len),
            Some(6)
        );
        assert!(files.get(3, "0/c/0/1/2/4", Instant::now()).is_none());
        // Too old: let go.
        assert!(files.get(3, "0/c/0/1/2/5", Instant::now()).is_none());
        assert_eq!(files.files.len(), 2);
    }

    #[test]
    fn a_file_seen_whole_in_the_page_cache_is_taken_as_held_for_a_second() {
        // Beside the sources, not in a /tmp that may be memory (where pages cannot drop).
        let mut named = tempfile::NamedTempFile::new_in(env!("CARGO_MANIFEST_DIR")).unwrap();
        named.write_all(&vec![7u8; 200 << 10]).unwrap();
        named.as_file().sync_all().unwrap();
        let meta = named.as_file().metadata().unwrap();
        let open = OpenFile::new(named.reopen().unwrap(), &meta, (0, 0));
        let (at, len) = (open.opened, open.len);
        // A part seen in the cache is not remembered, only the whole file.
        assert!(open.cached(5, 10, at));
        drop_pages(&open.file);
        assert!(!open.cached(0, len, at));
        page_cache::fill(&open.file, 0, len).unwrap();
        assert!(open.cached(0, len, at));
        // Dropped since: taken as held, whole or in part, for CACHED_FOR after the sighting.
        drop_pages(&open.file);
        let just_before =
            |after: Duration| at + after.checked_sub(Duration::from_millis(1)).unwrap();
        let last = just_before(CACHED_FOR);
        assert!(open.cached(0, len, last) && open.cached(100, 200, last));
        // A time taken before the sighting (by another thread) counts as at it.
        assert!(open.cached(0, len, at.checked_sub(Duration::from_secs(5)).unwrap()));
        // Then asked again.
        assert!(!open.cached(100, 200, at + CACHED_FOR));
        // A file read into the cache whole on a blocking thread is seen there.
        page_cache::fill(&open.file, 0, len).unwrap();
        open.saw_cached(0, len, at + CACHED_FOR);
        drop_pages(&open.file);
        assert!(open.cached(0, len, just_before(2 * CACHED_FOR)));
        assert!(!open.cached(0, len, at + 2 * CACHED_FOR));
    }

    #[test]
    fn a_file_changed_in_place_or_deleted_is_let_go() {
        let files = OpenFiles::unswept(16, Duration::from_mins(1));
        let (grown, a) = held(b"abcde", Duration::ZERO);
        let (same_length, b) = held(b"abcde", Duration::ZERO);
        let (deleted, c) = held(b"abcde", Duration::ZERO);
        for (key, open) in [("a", &a), ("b", &b), ("c", &c)] {
            files.insert(0, key, open.clone());
            assert!(files.get(0, key, Instant::now()).is_some() && open.unchanged());
        }
        grown.as_file().write_all(b"f").unwrap();
        // The same length, a later modification time.
        let later = std::time::SystemTime::now() + Duration::from_secs(5);
        same_length.as_file().set_modified(later).unwrap();
        deleted.close().unwrap();
        for (key, open) in [("a", &a), ("b", &b), ("c", &c)] {
            assert!(!open.unchanged(), "{key}");
            files.let_go(0, key, open);
        }
        assert_eq!(files.files.len(), 0);
        // Only the last holder closes it.
        assert_eq!(Arc::strong_count(&a), 1);
        // A file that took the place of the one let go stays.
        let (_d, d) = held(b"abcde", Duration::ZERO);
        files.insert(0, "a", d.clone());
        files.let_go(0, "a", &a);
        assert!(
            files
                .get(0, "a", Instant::now())
                .is_some_and(|open| Arc::ptr_eq(&open, &d) && open.unchanged())
        );
    }

    #[test]
    fn the_sweep_closes_the_files_held_too_long() {
        let files = OpenFiles::unswept(16, Duration::from_mins(1));
        let (_a, young) = held(b"a", Duration::ZERO);
        let (_b, old) = held(b"b", Duration::from_mins(2));
        files.insert(0, "young", young.clone());
        files.insert(0, "old", old.clone());
        files.close_stale();
        assert_eq!(files.files.len(), 1);
        assert_eq!((Arc::strong_count(&young), Arc::strong_count(&old)), (2, 1));
    }

    #[test]
    fn the_cache_is_at_most_a_quarter_of_the_open_file_limit() {
        assert_eq!(within_file_limit(4096, Some(20_000)), 4096);
        assert_eq!(within_file_limit(4096, Some(1024)), 256);
        assert_eq!(within_file_limit(4096, None), 4096);
        assert!(OpenFiles::new(0, Duration::from_mins(1)).is_none());
    }

    #[test]
    fn dropping_the_cache_stops_and_joins_its_sweep() {
        let files = OpenFiles::new(16, Duration::from_mins(1)).unwrap();
        let sweeper = files.sweeper.as_ref().unwrap().thread.thread().clone();
        assert_eq!(sweeper.name(), Some("open-files"));
        let (_a, a) = held(b"a", Duration::ZERO);
        files.insert(0, "a", a.clone());
        let started = Instant::now();
        drop(files);
        // Joined at once, not after the minute's sleep; the file it held is closed.
        assert!(started.elapsed() < Duration::from_secs(10));
        assert_eq!(Arc::strong_count(&a), 1);
    }
}
