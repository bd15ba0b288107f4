//! [`Slots`]: the client's concurrency limit (the endpoint's parallel slots), with waiting requests
//! admitted in order.
//!
//! A request that finds every slot taken waits; when a slot frees, the waiting request with the lowest
//! *order* takes it, ties going to the one that has waited longest. A request without an order comes
//! after every ordered one. The search gives each proposal its step as its order, so when more requests
//! are queued than the endpoint has slots, a round's proposals (and their repairs) are answered before
//! the next round's, which the search needs first; a plain counting semaphore let any waiter in.
//!
//! Owns only admission: what a request does with its slot, retries and timing are the client's
//! (`llm::client`).

use std::collections::BTreeSet;
use std::sync::{Condvar, Mutex};

/// A counting semaphore of `n` slots with ordered admission.
#[derive(Debug)]
pub(crate) struct Slots {
    state: Mutex<State>,
    cv: Condvar,
}

#[derive(Debug)]
struct State {
    free: usize,
    /// Waiting requests by (order, arrival).
    waiting: BTreeSet<(u64, u64)>,
    arrivals: u64,
}

/// A taken slot; dropping it frees the slot.
pub(crate) struct SlotGuard<'a>(&'a Slots);

impl Slots {
    /// `n` slots (at least one).
    pub(crate) fn new(n: usize) -> Self {
        Slots {
            state: Mutex::new(State {
                free: n.max(1),
                waiting: BTreeSet::new(),
                arrivals: 0,
            }),
            cv: Condvar::new(),
        }
    }

    /// Waits for a slot: a request with a lower `order` (`None`: after every ordered one), or an equal
    /// order and an earlier arrival, that is also waiting is admitted first.
    pub(crate) fn acquire(&self, order: Option<u64>) -> SlotGuard<'_> {
        let mut s = self.state.lock().unwrap_or_else(|p| p.into_inner());
        let key = (order.unwrap_or(u64::MAX), s.arrivals);
        s.arrivals += 1;
        s.waiting.insert(key);
        while !(s.free > 0 && s.waiting.first() == Some(&key)) {
            s = self.cv.wait(s).unwrap_or_else(|p| p.into_inner());
        }
        s.waiting.remove(&key);
        s.free -= 1;
        if s.free > 0 && !s.waiting.is_empty() {
            // The next in line may take another free slot.
            self.cv.notify_all();
        }
        SlotGuard(self)
    }
}

impl Drop for SlotGuard<'_> {
    fn drop(&mut self) {
        let mut s = self.0.state.lock().unwrap_or_else(|p| p.into_inner());
        s.free += 1;
        if !s.waiting.is_empty() {
            self.0.cv.notify_all();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;
    use std::time::Duration;

    /// Queues `orders` (one thread each, arriving in that sequence) behind a held slot, frees it and
    /// returns the order in which they were admitted.
    fn admitted(orders: &[Option<u64>]) -> Vec<Option<u64>> {
        let slots = Arc::new(Slots::new(1));
        let seen = Arc::new(Mutex::new(Vec::new()));
        let held = slots.acquire(Some(0));
        let mut threads = Vec::new();
        for (i, &o) in orders.iter().enumerate() {
            let (mine, seen) = (slots.clone(), seen.clone());
            threads.push(std::thread::spawn(move || {
                let _slot = mine.acquire(o);
                seen.lock().unwrap().push(o);
            }));
            // Wait until this one is queued, so arrivals are in `orders` order.
            while slots.state.lock().unwrap().waiting.len() < i + 1 {
                std::thread::sleep(Duration::from_millis(1));
            }
        }
        drop(held);
        for t in threads {
            t.join().unwrap();
        }
        Arc::try_unwrap(seen).unwrap().into_inner().unwrap()
    }

    #[test]
    fn waiting_requests_are_admitted_lowest_order_first_then_by_arrival() {
        assert_eq!(
            admitted(&[Some(9), None, Some(3), Some(3), Some(1)]),
            vec![Some(1), Some(3), Some(3), Some(9), None]
        );
        assert_eq!(admitted(&[None, None, None]), vec![None, None, None]);
    }

    #[test]
    fn no_more_than_n_hold_a_slot_at_once() {
        let slots = Arc::new(Slots::new(3));
        let inside = Arc::new(Mutex::new((0usize, 0usize)));
        let threads: Vec<_> = (0..12u64)
            .map(|i| {
                let (slots, inside) = (slots.clone(), inside.clone());
                std::thread::spawn(move || {
                    let _slot = slots.acquire(Some(i % 4));
                    {
                        let mut g = inside.lock().unwrap();
                        g.0 += 1;
                        g.1 = g.1.max(g.0);
                    }
                    std::thread::sleep(Duration::from_millis(5));
                    inside.lock().unwrap().0 -= 1;
                })
            })
            .collect();
        for t in threads {
            t.join().unwrap();
        }
        let (now, most) = *inside.lock().unwrap();
        assert_eq!(now, 0);
        assert_eq!(most, 3);
        // Every slot is free again: three can be taken at once without waiting.
        let _a = slots.acquire(None);
        let _b = slots.acquire(None);
        let _c = slots.acquire(None);
    }
}
