//! Work spread over threads with results in a fixed order, so that what is computed never
//! depends on the thread count.

use std::sync::atomic::{AtomicUsize, Ordering};

/// Threads for `items` items: `threads`, or one per core for 0, and never more than the items.
fn workers(threads: usize, items: usize) -> usize {
    let threads = match threads {
        0 => std::thread::available_parallelism().map_or(1, |t| t.get()),
        t => t,
    };
    threads.min(items.max(1))
}

/// `f(0), f(1), ..., f(count - 1)` computed on `threads` threads (0: one per core), in index
/// order. Items are handed out one at a time, so uneven items balance.
pub fn map<T: Send>(count: usize, threads: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    let threads = workers(threads, count);
    let next = AtomicUsize::new(0);
    let mut done: Vec<(usize, T)> = std::thread::scope(|s| {
        let workers: Vec<_> = (0..threads)
            .map(|_| {
                s.spawn(|| {
                    let mut done = Vec::new();
                    loop {
                        let i = next.fetch_add(1, Ordering::Relaxed);
                        if i >= count {
                            return done;
                        }
                        done.push((i, f(i)));
                    }
                })
            })
            .collect();
        workers.into_iter().flat_map(|w| w.join().expect("a worker thread panicked")).collect()
    });
    done.sort_by_key(|(i, _)| *i);
    done.into_iter().map(|(_, t)| t).collect()
}

/// `f(0), ..., f(count - 1)` in index order, computed `chunk_len` items at a time on one thread
/// per core; below two chunks on the calling thread alone (spawning costs more than it saves).
pub fn map_in_chunks<T: Send>(count: usize, chunk_len: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    let chunk_len = chunk_len.max(1);
    let threads = if count >= 2 * chunk_len { 0 } else { 1 };
    let chunks = map(count.div_ceil(chunk_len), threads, |c| {
        (c * chunk_len..((c + 1) * chunk_len).min(count)).map(&f).collect::<Vec<T>>()
    });
    chunks.into_iter().flatten().collect()
}

/// `f(index, chunk)` for every `chunk_len`-long chunk of `out` (the last may be shorter), on
/// `threads` threads (0: one per core); each chunk is written by one call alone, so the result
/// does not depend on the thread count when `f` does not.
pub fn for_each_chunk<T: Send>(out: &mut [T], chunk_len: usize, threads: usize, f: impl Fn(usize, &mut [T]) + Sync) {
    let chunks: Vec<(usize, &mut [T])> = out.chunks_mut(chunk_len.max(1)).enumerate().collect();
    let threads = workers(threads, chunks.len());
    let queue = std::sync::Mutex::new(chunks.into_iter());
    std::thread::scope(|s| {
        for _ in 0..threads {
            s.spawn(|| {
                loop {
                    let Some((i, chunk)) = queue.lock().expect("a worker thread panicked").next() else { return };
                    f(i, chunk);
                }
            });
        }
    });
}

#[cfg(test)]
mod tests {
    #[test]
    fn results_come_in_index_order_for_any_thread_count() {
        for threads in [0, 1, 2, 7] {
            assert_eq!(super::map(10, threads, |i| i * i), (0..10).map(|i| i * i).collect::<Vec<_>>());
        }
        assert!(super::map(0, 3, |i| i).is_empty());
    }

    #[test]
    fn chunked_results_come_in_index_order() {
        for (count, chunk) in [(0, 4), (3, 4), (10, 4), (10, 3), (9, 3)] {
            assert_eq!(super::map_in_chunks(count, chunk, |i| i * i), (0..count).map(|i| i * i).collect::<Vec<_>>());
        }
    }

    #[test]
    fn every_chunk_is_written_once_for_any_thread_count() {
        for threads in [0, 1, 3] {
            let mut out = vec![0usize; 10];
            super::for_each_chunk(&mut out, 3, threads, |i, chunk| chunk.iter_mut().for_each(|x| *x += i + 1));
            assert_eq!(out, [1, 1, 1, 2, 2, 2, 3, 3, 3, 4]);
        }
    }
}
