//! Progress reporting: an indicatif bar on a terminal, plain log lines otherwise (CI logs,
//! pipes), so long work is always visible.

use std::io::IsTerminal;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressStyle};

/// A progress reporter over `total` steps.
pub struct Progress {
    bar: Option<ProgressBar>,
    label: String,
    total: u64,
    done: u64,
    start: Instant,
    last_line: Instant,
}

impl Progress {
    /// Start reporting `label` over `total` steps.
    pub fn new(label: &str, total: u64) -> Self {
        Self::starting_at(label, total, 0)
    }

    /// Start reporting `label` over `total` steps of which `done` are already done (a resumed
    /// run): the count starts there and the rate / ETA count only the steps of this session.
    pub fn starting_at(label: &str, total: u64, done: u64) -> Self {
        let bar = if std::io::stderr().is_terminal() {
            let b = ProgressBar::new(total);
            b.set_style(
                ProgressStyle::with_template(
                    "{prefix:>12} [{bar:40}] {pos}/{len} {msg} ({elapsed}, eta {eta})",
                )
                .expect("valid template")
                .progress_chars("=> "),
            );
            b.set_prefix(label.to_string());
            b.set_position(done);
            b.reset_eta();
            Some(b)
        } else {
            None
        };
        Progress {
            bar,
            label: label.to_string(),
            total,
            done,
            start: Instant::now(),
            last_line: Instant::now(),
        }
    }

    /// Advance by `n` steps with a status message.
    pub fn inc(&mut self, n: u64, msg: &str) {
        self.done += n;
        match &self.bar {
            Some(b) => {
                b.set_message(msg.to_string());
                b.inc(n);
            }
            None => {
                if self.last_line.elapsed() >= Duration::from_secs(5) || self.done == self.total {
                    self.last_line = Instant::now();
                    eprintln!(
                        "{}: {}/{} {} ({:.1} s)",
                        self.label,
                        self.done,
                        self.total,
                        msg,
                        self.start.elapsed().as_secs_f64()
                    );
                }
            }
        }
    }

    /// Finish with a final message.
    pub fn finish(self, msg: &str) {
        match self.bar {
            Some(b) => b.finish_with_message(msg.to_string()),
            None => eprintln!(
                "{}: done {} ({:.1} s)",
                self.label,
                msg,
                self.start.elapsed().as_secs_f64()
            ),
        }
    }
}
