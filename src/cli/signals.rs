//! SIGINT (Ctrl-C) and SIGTERM (what batch schedulers send) for `unispine train`: the first
//! signal asks the run to stop after the current iteration (it then writes a checkpoint and a
//! `metrics.json` with `"completed": false`); the CLI then exits with 128 + the signal number
//! (130 for SIGINT, 143 for SIGTERM). A second signal exits at once with that code.

use std::sync::atomic::{AtomicBool, AtomicI32, Ordering};

/// Set by the first signal; the training loop polls it.
pub static STOP: AtomicBool = AtomicBool::new(false);
static SIGNAL: AtomicI32 = AtomicI32::new(0);

extern "C" fn on_signal(sig: libc::c_int) {
    // Only async-signal-safe calls here: atomics, write(2), _exit(2).
    if SIGNAL.swap(sig, Ordering::SeqCst) != 0 {
        let msg = b"\nsecond signal: exiting without a checkpoint\n";
        unsafe {
            libc::write(2, msg.as_ptr().cast(), msg.len());
            libc::_exit(128 + sig);
        }
    }
    STOP.store(true, Ordering::SeqCst);
    let msg = b"\nsignal received: stopping after this iteration and saving the run ...\n";
    unsafe {
        libc::write(2, msg.as_ptr().cast(), msg.len());
    }
}

/// Install the handler for SIGINT and SIGTERM.
pub fn install() -> anyhow::Result<()> {
    for sig in [libc::SIGINT, libc::SIGTERM] {
        let handler = on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t;
        // SAFETY: the handler only touches atomics and calls async-signal-safe functions.
        if unsafe { libc::signal(sig, handler) } == libc::SIG_ERR {
            anyhow::bail!("cannot install the handler of signal {sig}");
        }
    }
    Ok(())
}

/// The exit code a received signal asks for (128 + signal number), if any.
pub fn exit_code() -> Option<i32> {
    match SIGNAL.load(Ordering::SeqCst) {
        0 => None,
        s => Some(128 + s),
    }
}
