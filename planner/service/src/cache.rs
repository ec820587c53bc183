//! A small least-recently-used cache of expensive, deterministic builds (the P-F generators of a
//! map + settings). Concurrent requests for the same key build once: the others wait for that
//! build instead of repeating it.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex, OnceLock, PoisonError};

/// LRU cache with at most `capacity` entries; the front is the most recently used.
#[derive(Debug)]
pub struct BuildCache<K, V> {
    capacity: usize,
    entries: Mutex<VecDeque<(K, Arc<OnceLock<V>>)>>,
}

impl<K: PartialEq, V: Clone> BuildCache<K, V> {
    /// A cache holding up to `capacity` builds (0 disables caching: every call builds).
    pub fn new(capacity: usize) -> Self {
        Self {
            capacity,
            entries: Mutex::new(VecDeque::with_capacity(capacity)),
        }
    }

    /// The value for `key`, built with `build` if it is not cached. Returns the value and whether
    /// it came from the cache.
    pub fn get_or_build(&self, key: K, build: impl FnOnce() -> V) -> (V, bool) {
        if self.capacity == 0 {
            return (build(), false);
        }
        let cell = {
            let mut entries = self.entries.lock().unwrap_or_else(PoisonError::into_inner);
            match entries.iter().position(|(k, _)| *k == key) {
                Some(i) => {
                    let entry = entries.remove(i).expect("index from position is valid");
                    let cell = Arc::clone(&entry.1);
                    entries.push_front(entry);
                    cell
                }
                None => {
                    let cell = Arc::new(OnceLock::new());
                    entries.push_front((key, Arc::clone(&cell)));
                    entries.truncate(self.capacity);
                    cell
                }
            }
        };
        // Built outside the list lock: other keys stay usable during a long build, and callers
        // with the same key block in get_or_init until the first build is done.
        let mut built_here = false;
        let value = cell.get_or_init(|| {
            built_here = true;
            build()
        });
        (value.clone(), !built_here)
    }

    /// Entries currently held.
    /// Drops the entry of `key`, if held (a build that must not be reused, e.g. one stopped by
    /// its request's time limit).
    pub fn evict(&self, key: &K) {
        let mut entries = self.entries.lock().unwrap_or_else(PoisonError::into_inner);
        entries.retain(|(k, _)| k != key);
    }

    pub fn len(&self) -> usize {
        self.entries
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .len()
    }

    /// True when nothing is cached.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

    #[test]
    fn hits_reuse_and_the_least_recently_used_entry_is_evicted() {
        let cache = BuildCache::new(2);
        let builds = AtomicUsize::new(0);
        let get = |k: u32| {
            cache.get_or_build(k, || {
                builds.fetch_add(1, Ordering::SeqCst);
                k * 10
            })
        };
        assert_eq!(get(1), (10, false));
        assert_eq!(get(2), (20, false));
        assert_eq!(get(1), (10, true)); // 1 is now the most recent
        assert_eq!(get(3), (30, false)); // evicts 2
        assert_eq!(cache.len(), 2);
        assert_eq!(get(1), (10, true));
        assert_eq!(get(2), (20, false)); // rebuilt
        assert_eq!(builds.load(Ordering::SeqCst), 4);
    }

    #[test]
    fn concurrent_requests_for_one_key_build_once() {
        let cache = BuildCache::new(4);
        let builds = AtomicUsize::new(0);
        std::thread::scope(|s| {
            for _ in 0..8 {
                s.spawn(|| {
                    let (v, _) = cache.get_or_build("k", || {
                        builds.fetch_add(1, Ordering::SeqCst);
                        std::thread::sleep(std::time::Duration::from_millis(20));
                        7
                    });
                    assert_eq!(v, 7);
                });
            }
        });
        assert_eq!(builds.load(Ordering::SeqCst), 1);
    }

    #[test]
    fn zero_capacity_always_builds() {
        let cache = BuildCache::new(0);
        assert_eq!(cache.get_or_build(1, || 5), (5, false));
        assert_eq!(cache.get_or_build(1, || 6), (6, false));
        assert!(cache.is_empty());
    }
}
