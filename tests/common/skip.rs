//! Loud notes for optional checks that did not run.

use std::io::Write;

/// Say that the optional check `what` did not run and why, on the process's stderr directly:
/// the test harness keeps the `println!` / `eprintln!` output of a passing test to itself, so a
/// note written that way would never be seen. Under `CI=true` a skipped independent reference
/// is an error instead (the caller asserts that).
pub fn skipped(what: &str, why: &str) {
    let line = format!("\n*** SKIPPED: {what}: {why} ***\n\n");
    let _ = std::io::stderr().lock().write_all(line.as_bytes());
}
