//! A cache bounded by memory: values by key, each with its size in bytes,
//! the least recently used evicted once the sizes pass a budget, except
//! values someone still holds (a running render's optics). One type for the
//! session's prepared optics and a worker's.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

/// The default budget: 2 GiB, about a hundred sets of clear-sky optics.
pub const DEFAULT_BUDGET_BYTES: u64 = 2 << 30;

struct Entry<V> {
    value: Arc<V>,
    bytes: u64,
    /// The tick of the last get or insert.
    used: u64,
}

struct Inner<V> {
    entries: HashMap<String, Entry<V>>,
    tick: u64,
    bytes: u64,
}

/// Values by key, at most `budget` bytes of them (more only while the
/// values over the budget are all in use).
pub struct MemoryLru<V> {
    budget: u64,
    inner: Mutex<Inner<V>>,
}

impl<V> MemoryLru<V> {
    pub fn new(budget_bytes: u64) -> MemoryLru<V> {
        MemoryLru { budget: budget_bytes, inner: Mutex::new(Inner { entries: HashMap::new(), tick: 0, bytes: 0 }) }
    }

    pub fn budget(&self) -> u64 {
        self.budget
    }

    /// The value of `key`, now the most recently used.
    pub fn get(&self, key: &str) -> Option<Arc<V>> {
        let mut g = self.inner.lock().unwrap();
        g.tick += 1;
        let tick = g.tick;
        let e = g.entries.get_mut(key)?;
        e.used = tick;
        Some(e.value.clone())
    }

    /// Whether `key` is held (without touching it).
    pub fn contains(&self, key: &str) -> bool {
        self.inner.lock().unwrap().entries.contains_key(key)
    }

    /// Keeps `value` of `bytes` under `key` (an entry already there wins and
    /// is returned), then evicts the least recently used values nobody
    /// else holds until the sizes fit the budget.
    pub fn insert(&self, key: String, value: Arc<V>, bytes: u64) -> Arc<V> {
        let mut g = self.inner.lock().unwrap();
        g.tick += 1;
        let tick = g.tick;
        let kept = match g.entries.get_mut(&key) {
            Some(e) => {
                e.used = tick;
                e.value.clone()
            }
            None => {
                g.bytes += bytes;
                g.entries.insert(key, Entry { value: value.clone(), bytes, used: tick });
                value
            }
        };
        Self::evict(&mut g, self.budget);
        kept
    }

    fn evict(g: &mut Inner<V>, budget: u64) {
        while g.bytes > budget {
            // The caller of `insert` holds its value, so it is never the victim.
            let victim = g
                .entries
                .iter()
                .filter(|(_, e)| Arc::strong_count(&e.value) == 1)
                .min_by_key(|(_, e)| e.used)
                .map(|(k, _)| k.clone());
            let Some(k) = victim else { break };
            let e = g.entries.remove(&k).unwrap();
            g.bytes -= e.bytes;
        }
    }

    /// The keys held, most recently used first.
    pub fn keys(&self) -> Vec<String> {
        let g = self.inner.lock().unwrap();
        let mut k: Vec<(&String, u64)> = g.entries.iter().map(|(k, e)| (k, e.used)).collect();
        k.sort_by_key(|&(_, u)| std::cmp::Reverse(u));
        k.into_iter().map(|(k, _)| k.clone()).collect()
    }

    /// The bytes held.
    pub fn bytes(&self) -> u64 {
        self.inner.lock().unwrap().bytes
    }

    pub fn len(&self) -> usize {
        self.inner.lock().unwrap().entries.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_least_recently_used_goes_first() {
        let c = MemoryLru::new(30);
        drop(c.insert("a".into(), Arc::new(1), 10));
        drop(c.insert("b".into(), Arc::new(2), 10));
        drop(c.insert("c".into(), Arc::new(3), 10));
        assert_eq!(c.bytes(), 30);
        // Touch a: b is now the oldest.
        assert_eq!(*c.get("a").unwrap(), 1);
        drop(c.insert("d".into(), Arc::new(4), 10));
        assert!(!c.contains("b") && c.contains("a") && c.contains("c") && c.contains("d"));
        assert_eq!(c.bytes(), 30);
        assert_eq!(c.keys(), vec!["d", "a", "c"]);
        // One value larger than the budget, unheld: it evicts everything,
        // then itself once nobody holds it at the next insert.
        let big = c.insert("big".into(), Arc::new(5), 100);
        assert_eq!(c.keys(), vec!["big"]);
        drop(big);
        drop(c.insert("e".into(), Arc::new(6), 10));
        assert_eq!(c.keys(), vec!["e"]);
        assert_eq!(c.bytes(), 10);
    }

    #[test]
    fn values_in_use_are_never_evicted() {
        let c = MemoryLru::new(20);
        let a = c.insert("a".into(), Arc::new("a"), 10);
        let b = c.insert("b".into(), Arc::new("b"), 10);
        // Over the budget, but a and b are both held (a running task each).
        let x = c.insert("x".into(), Arc::new("x"), 10);
        assert_eq!(c.len(), 3);
        assert_eq!(c.bytes(), 30);
        // Once a is let go it is the one evicted, not the held b or x.
        drop(a);
        drop(c.insert("y".into(), Arc::new("y"), 0));
        assert!(!c.contains("a") && c.contains("b") && c.contains("x") && c.contains("y"));
        assert_eq!((*b, *x), ("b", "x"));
        // An existing key keeps its first value.
        let again = c.insert("b".into(), Arc::new("other"), 10);
        assert_eq!(*again, "b");
        assert_eq!(c.bytes(), 20);
    }
}
