//! Deterministic parallelism helpers (the determinism rule of `paper_notes.md`, Conventions).
//!
//! rayon's float `sum`/`reduce`/`fold` change bits with the thread count and even from run to
//! run. Every parallel reduction in this crate goes through fixed-size chunks whose partial
//! results are collected in order and reduced sequentially.

use rayon::prelude::*;

/// Fixed chunk length for parallel reductions. Never derived from the thread count.
pub const CHUNK: usize = 4096;

/// Sum of `x` in f64, bit-identical for any thread count.
pub fn det_sum<T: Copy + Into<f64> + Sync>(x: &[T]) -> f64 {
    x.par_chunks(CHUNK)
        .map(|c| c.iter().map(|&v| v.into()).sum::<f64>())
        .collect::<Vec<_>>()
        .into_iter()
        .sum()
}

/// Sum of `f(i)` for `i in 0..n`, in f64, bit-identical for any thread count.
pub fn det_sum_by<F: Fn(usize) -> f64 + Sync>(n: usize, f: F) -> f64 {
    let chunks = n.div_ceil(CHUNK);
    (0..chunks)
        .into_par_iter()
        .map(|c| {
            let lo = c * CHUNK;
            let hi = (lo + CHUNK).min(n);
            (lo..hi).map(&f).sum::<f64>()
        })
        .collect::<Vec<_>>()
        .into_iter()
        .sum()
}

/// The two sums of `f(i) = (a_i, b_i)` for `i in 0..n` in one pass, each bit-identical to
/// [`det_sum_by`] of its component (the same chunks, each summed in order from -0.0 as
/// `Iterator::sum` does, the chunks' sums added in order).
pub fn det_sum2_by<F: Fn(usize) -> (f64, f64) + Sync>(n: usize, f: F) -> (f64, f64) {
    let chunks = n.div_ceil(CHUNK);
    (0..chunks)
        .into_par_iter()
        .map(|c| {
            let lo = c * CHUNK;
            let hi = (lo + CHUNK).min(n);
            (lo..hi)
                .map(&f)
                .fold((-0.0, -0.0), |(a, b), (x, y)| (a + x, b + y))
        })
        .collect::<Vec<_>>()
        .into_iter()
        .fold((-0.0, -0.0), |(a, b), (x, y)| (a + x, b + y))
}

/// Lock `m`. A lock poisoned by a panic on another thread (which rayon or the thread scope
/// re-raises on the caller) still holds valid data, so its guard is taken rather than a second
/// panic raised.
pub fn lock<T>(m: &std::sync::Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// Check a count of parallel workers (`--jobs`, `--threads`): the allowed range is
/// [1, 8 x the available cores]. More only costs memory (stacks, processes) and time: results
/// never depend on it.
pub fn check_workers(flag: &str, n: usize) -> crate::Result<()> {
    let cores = std::thread::available_parallelism().map_or(1, |c| c.get());
    if n == 0 || n > 8 * cores {
        return Err(crate::Error::invalid(
            flag,
            format!(
                "{n} is outside the allowed range [1, {}] (8 x the {cores} cores)",
                8 * cores
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn det_sum_is_thread_count_invariant() {
        let x: Vec<f32> = (0..100_003)
            .map(|i| ((i * 7919) % 1000) as f32 * 1e-3 - 0.4)
            .collect();
        let mut bits = Vec::new();
        for t in [1, 2, 8] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(t)
                .build()
                .unwrap();
            bits.push(pool.install(|| det_sum(&x)).to_bits());
            bits.push(
                pool.install(|| det_sum_by(x.len(), |i| x[i] as f64))
                    .to_bits(),
            );
        }
        assert!(bits.iter().step_by(2).all(|b| *b == bits[0]));
        assert!(bits.iter().skip(1).step_by(2).all(|b| *b == bits[1]));
        assert_eq!(bits[0], bits[1]);
    }

    #[test]
    fn det_sum2_by_gives_the_bits_of_two_det_sums() {
        // Signed zeros alone (the sum of -0.0s is -0.0), a chunk and a half, and values whose
        // order matters in f64.
        let a: Vec<f64> = (0..6151)
            .map(|i| match i % 5 {
                0 => -0.0,
                1 => 1e16,
                2 => -1e16,
                _ => (i as f64).sin() * 1e-3,
            })
            .collect();
        let b: Vec<f64> = vec![-0.0; 6151];
        for n in [0, 1, 5, 4096, 6151] {
            let (s, t) = det_sum2_by(n, |i| (a[i], b[i]));
            assert_eq!(s.to_bits(), det_sum_by(n, |i| a[i]).to_bits(), "n = {n}");
            assert_eq!(t.to_bits(), det_sum_by(n, |i| b[i]).to_bits(), "n = {n}");
        }
        assert!(det_sum2_by(3, |i| (b[i], b[i])).0.is_sign_negative());
    }
}
