//! Frames in flight: `cog-gpu detect --in-flight N` and `cog-gpu bench --detect --in-flight N` detect
//! several frames at once, so that one frame's CPU stages (preprocessing, yaw grids, windows, lattices, the
//! packing of hypotheses for the GPU, NMS, layout) overlap another frame's GPU work. A frame on the GPU path
//! alternates between the two, and on a machine with a fast GPU the CPU stages are most of its wall time
//! (README, "End to end: `cog-gpu bench --detect`").
//!
//! The frames' own parallel work still runs on rayon's global pool: the `N` frames are driven from `N`
//! threads outside the pool (a thread blocked in a frame's `par_iter` holds no pool thread), and the GPU
//! context serialises their batches through its buffer-pool sets. Each frame's detections are those of a
//! frame detected alone (the paths are deterministic per hypothesis; `bench --detect --in-flight` checks it).

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Mutex;

/// Calls `work(index, item)` for every item, `in_flight` items at a time (at least one), and returns the
/// results in item order. Items start in order; once `stop(result)` holds for a finished item, no further
/// item starts (those already started finish) and the items never started get `None`. With `in_flight`
/// 1 every item runs on the calling thread, one after the other, exactly as a plain loop.
pub fn in_flight<T: Sync, R: Send>(
    items: &[T],
    in_flight: usize,
    work: impl Fn(usize, &T) -> R + Sync,
    stop: impl Fn(&R) -> bool + Sync,
) -> Vec<Option<R>> {
    let mut results: Vec<Option<R>> = std::iter::repeat_with(|| None).take(items.len()).collect();
    if in_flight <= 1 || items.len() <= 1 {
        for (n, item) in items.iter().enumerate() {
            let result = work(n, item);
            let stopping = stop(&result);
            results[n] = Some(result);
            if stopping {
                break;
            }
        }
        return results;
    }
    let next = AtomicUsize::new(0);
    let stopped = AtomicBool::new(false);
    let slots = Mutex::new(results);
    std::thread::scope(|scope| {
        for _ in 0..in_flight.min(items.len()) {
            scope.spawn(|| loop {
                if stopped.load(Ordering::SeqCst) {
                    break;
                }
                let n = next.fetch_add(1, Ordering::SeqCst);
                let Some(item) = items.get(n) else { break };
                let result = work(n, item);
                if stop(&result) {
                    stopped.store(true, Ordering::SeqCst);
                }
                slots.lock().unwrap_or_else(|p| p.into_inner())[n] = Some(result);
            });
        }
    });
    slots.into_inner().unwrap_or_else(|p| p.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn results_come_in_item_order_whatever_the_finishing_order() {
        let items: Vec<u64> = (0..12).collect();
        for in_flight in [1, 2, 3, 5, 20] {
            // Earlier items sleep longer, so with several in flight they finish after later ones.
            let out = super::in_flight(
                &items,
                in_flight,
                |n, &x| {
                    std::thread::sleep(Duration::from_millis(12 - x));
                    (n, x * x)
                },
                |_| false,
            );
            let expected: Vec<Option<(usize, u64)>> = items.iter().map(|&x| Some((x as usize, x * x))).collect();
            assert_eq!(out, expected, "in_flight {in_flight}");
        }
    }

    #[test]
    fn at_most_in_flight_items_run_at_once() {
        let items = vec![(); 16];
        let running = AtomicUsize::new(0);
        let most = AtomicUsize::new(0);
        super::in_flight(
            &items,
            3,
            |_, _| {
                let now = running.fetch_add(1, Ordering::SeqCst) + 1;
                most.fetch_max(now, Ordering::SeqCst);
                std::thread::sleep(Duration::from_millis(5));
                running.fetch_sub(1, Ordering::SeqCst);
            },
            |_| false,
        );
        let most = most.load(Ordering::SeqCst);
        assert!(most <= 3, "{most} items ran at once");
        // With 16 items of 5 ms and three threads, two overlapping is all but certain; not asserted (timing).
    }

    #[test]
    fn a_stop_result_starts_no_further_item() {
        let items: Vec<usize> = (0..10).collect();
        // One at a time: items after the stopping one never start.
        let out = super::in_flight(&items, 1, |_, &x| x, |&x| x == 3);
        assert_eq!(out.iter().filter(|r| r.is_some()).count(), 4);
        assert_eq!(out[3], Some(3));
        assert!(out[4..].iter().all(Option::is_none));
        // Two at a time: every item before the stopping one has started (items start in order) and the
        // stopping one finished. The others sleep, so the last items could only start if the stopping
        // thread stalled for ~50 ms between its result and its flag.
        let out = super::in_flight(
            &items,
            2,
            |_, &x| {
                if x != 3 {
                    std::thread::sleep(Duration::from_millis(10));
                }
                x
            },
            |&x| x == 3,
        );
        assert!(out[..=3].iter().enumerate().all(|(n, r)| *r == Some(n)), "{out:?}");
        assert!(out[9].is_none(), "{out:?}");
    }
}
