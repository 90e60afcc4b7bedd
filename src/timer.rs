//! The clocks of the stage timers (the Gaussian trainer's [`crate::train::stages`], the neural
//! fields' [`crate::field::train::StageTimes`] and the benchmarks): wall time, and CPU time,
//! which other processes on a shared machine do not inflate. Each reads its clocks only when
//! it is on, and changes nothing the timed code computes.

use std::time::Instant;

/// A stopwatch of the calling thread's CPU time (so that other processes on a shared machine
/// do not inflate it), read only when enabled.
pub struct ThreadClock(Option<f64>);

impl ThreadClock {
    /// Started now when `on` (else it never reads the clock).
    pub fn new(on: bool) -> Self {
        ThreadClock(on.then(|| cpu_seconds(libc::CLOCK_THREAD_CPUTIME_ID)))
    }
    /// Seconds since the last lap (0 when disabled), restarting.
    pub fn lap(&mut self) -> f64 {
        match &mut self.0 {
            Some(t) => {
                let now = cpu_seconds(libc::CLOCK_THREAD_CPUTIME_ID);
                let d = now - *t;
                *t = now;
                d
            }
            None => 0.0,
        }
    }
}

/// CPU seconds of the clock `id` (`CLOCK_THREAD_CPUTIME_ID`, `CLOCK_PROCESS_CPUTIME_ID`); NaN
/// when the OS does not tell.
pub fn cpu_seconds(id: libc::clockid_t) -> f64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid timespec to write to.
    if unsafe { libc::clock_gettime(id, &mut ts) } != 0 {
        return f64::NAN;
    }
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}

/// A lap clock (wall and process CPU time) that reads the clocks only when `on`.
pub struct Laps {
    last: Option<(Instant, f64)>,
    start: Option<(Instant, f64)>,
}

fn now() -> (Instant, f64) {
    (Instant::now(), cpu_seconds(libc::CLOCK_PROCESS_CPUTIME_ID))
}

impl Laps {
    /// Started now when `on` (else it never reads the clocks).
    pub fn new(on: bool) -> Self {
        let t = on.then(now);
        Laps { last: t, start: t }
    }

    /// (wall, CPU) seconds since the previous lap ((0, 0) when off).
    #[inline]
    pub fn lap(&mut self) -> (f64, f64) {
        match &mut self.last {
            Some(t) => {
                let n = now();
                let d = ((n.0 - t.0).as_secs_f64(), n.1 - t.1);
                *t = n;
                d
            }
            None => (0.0, 0.0),
        }
    }

    /// (wall, CPU) seconds since the clock started ((0, 0) when off).
    pub fn total(&self) -> (f64, f64) {
        match self.start {
            Some(s) => {
                let n = now();
                ((n.0 - s.0).as_secs_f64(), n.1 - s.1)
            }
            None => (0.0, 0.0),
        }
    }
}
