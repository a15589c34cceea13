//! Work spread over threads with results in a fixed order, so that what is computed never
//! depends on the thread count.
//!
//! The work runs on rayon's pool, started once: the cloth's collision passes call these dozens
//! of times a frame, and spawning threads for each call cost about 5 % of the frame.

use rayon::prelude::*;

/// Runs `f` on `threads` threads: 1 on the calling thread, 0 on the shared pool (one per core),
/// another count on a pool of its own.
fn on_threads<R: Send>(threads: usize, f: impl FnOnce(bool) -> R + Send) -> R {
    match threads {
        0 => f(true),
        1 => f(false),
        t => match rayon::ThreadPoolBuilder::new().num_threads(t).build() {
            Ok(pool) => pool.install(|| f(true)),
            // No threads to be had: the same result on this one.
            Err(_) => f(false),
        },
    }
}

/// `f(0), f(1), ..., f(count - 1)` computed on `threads` threads (0: one per core), in index
/// order. Items are handed out one at a time, so uneven items balance.
pub fn map<T: Send>(count: usize, threads: usize, f: impl Fn(usize) -> T + Sync + Send) -> Vec<T> {
    on_threads(threads, |parallel| {
        if parallel && count > 1 {
            (0..count).into_par_iter().with_max_len(1).map(&f).collect()
        } else {
            (0..count).map(&f).collect()
        }
    })
}

/// `f(0), ..., f(count - 1)` in index order, computed `chunk_len` items at a time on one thread
/// per core; below two chunks on the calling thread alone (handing out costs more than it saves).
pub fn map_in_chunks<T: Send>(count: usize, chunk_len: usize, f: impl Fn(usize) -> T + Sync + Send) -> Vec<T> {
    let chunk_len = chunk_len.max(1);
    let chunks = map(count.div_ceil(chunk_len), chunk_threads(count, chunk_len), |c| {
        (c * chunk_len..((c + 1) * chunk_len).min(count)).map(&f).collect::<Vec<T>>()
    });
    chunks.into_iter().flatten().collect()
}

/// Each of `count` items' lists (`find(i, list)` appends item `i`'s), found as
/// [`map_in_chunks`] finds its items and laid out in item order as CSR: item `i`'s are
/// `out[starts[i]..starts[i + 1]]`. One list per chunk, not per item.
pub fn csr_in_chunks<T: Send>(
    count: usize,
    chunk_len: usize,
    starts: &mut Vec<u32>,
    out: &mut Vec<T>,
    find: impl Fn(usize, &mut Vec<T>) + Sync + Send,
) {
    starts.clear();
    out.clear();
    starts.push(0);
    for (found, ends) in lists_in_chunks(count, chunk_len, find) {
        let base = out.len() as u32;
        starts.extend(ends.iter().map(|&(end, ())| base + end));
        out.extend(found);
    }
}

/// Each of `count` items' lists (`find(i, list)` appends item `i`'s and says whether to count
/// it), found as [`csr_in_chunks`] finds them and appended to `out` in item order; returns how
/// many items `find` counted. For lists that carry their item.
pub fn flat_in_chunks<T: Send>(
    count: usize,
    chunk_len: usize,
    out: &mut Vec<T>,
    find: impl Fn(usize, &mut Vec<T>) -> bool + Sync + Send,
) -> usize {
    out.clear();
    let mut counted = 0;
    for (found, ends) in lists_in_chunks(count, chunk_len, find) {
        counted += ends.iter().filter(|(_, c)| *c).count();
        out.extend(found);
    }
    counted
}

/// One chunk's items' lists appended into one, and each item's end in it with what `find`
/// returned for it.
type ChunkLists<T, R> = (Vec<T>, Vec<(u32, R)>);

/// [`ChunkLists`] of every `chunk_len` items, in order.
fn lists_in_chunks<T: Send, R: Send>(
    count: usize,
    chunk_len: usize,
    find: impl Fn(usize, &mut Vec<T>) -> R + Sync + Send,
) -> Vec<ChunkLists<T, R>> {
    let chunk_len = chunk_len.max(1);
    map(count.div_ceil(chunk_len), chunk_threads(count, chunk_len), |c| {
        let (mut found, mut ends) = (Vec::new(), Vec::with_capacity(chunk_len));
        for i in c * chunk_len..((c + 1) * chunk_len).min(count) {
            let r = find(i, &mut found);
            ends.push((found.len() as u32, r));
        }
        (found, ends)
    })
}

/// One thread per core from two chunks up; below, the calling thread alone (handing out costs
/// more than it saves).
fn chunk_threads(count: usize, chunk_len: usize) -> usize {
    if count >= 2 * chunk_len { 0 } else { 1 }
}

/// `f(index, chunk)` for every `chunk_len`-long chunk of `out` (the last may be shorter), on
/// `threads` threads (0: one per core); each chunk is written by one call alone, so the result
/// does not depend on the thread count when `f` does not.
pub fn for_each_chunk<T: Send>(
    out: &mut [T],
    chunk_len: usize,
    threads: usize,
    f: impl Fn(usize, &mut [T]) + Sync + Send,
) {
    let chunk_len = chunk_len.max(1);
    on_threads(threads, |parallel| {
        if parallel && out.len() > chunk_len {
            out.par_chunks_mut(chunk_len).with_max_len(1).enumerate().for_each(|(i, chunk)| f(i, chunk));
        } else {
            out.chunks_mut(chunk_len).enumerate().for_each(|(i, chunk)| f(i, chunk));
        }
    })
}

/// `f(item)` for every item on one thread per core, in any order: for items that work on data
/// of their own, whose results then do not depend on the order.
pub fn for_each<T: Send>(items: Vec<T>, f: impl Fn(T) + Sync + Send) {
    items.into_par_iter().with_max_len(1).for_each(f);
}

#[cfg(test)]
mod tests {
    #[test]
    fn lists_found_in_chunks_are_laid_out_in_item_order() {
        // Item i has i % 5 entries, 1000 i + j: several chunks, found on the cores.
        let count = 3 * 64 + 17;
        let (mut starts, mut out) = (vec![9], vec![9]);
        super::csr_in_chunks(count, 64, &mut starts, &mut out, |i, found| {
            found.extend((0..i as u32 % 5).map(|j| 1000 * i as u32 + j));
        });
        let mut want_starts = vec![0u32];
        let mut want = Vec::new();
        for i in 0..count as u32 {
            want.extend((0..i % 5).map(|j| 1000 * i + j));
            want_starts.push(want.len() as u32);
        }
        assert_eq!(starts, want_starts);
        assert_eq!(out, want);
        // The same lists appended flat, counting the items with four entries.
        let mut flat = vec![9];
        let counted = super::flat_in_chunks(count, 64, &mut flat, |i, found| {
            found.extend((0..i as u32 % 5).map(|j| 1000 * i as u32 + j));
            i % 5 == 4
        });
        assert_eq!(flat, want);
        assert_eq!(counted, (0..count).filter(|i| i % 5 == 4).count());
    }

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
