//! Helpers shared by the integration tests (each test file uses some of them).

#![allow(dead_code)]

pub mod cli;
pub mod golden;
pub mod hostile;
pub mod skip;
pub mod tiny;

/// The message of the panic `f` raises (`&str` or `String`), or `None` when it returns.
pub fn panic_text(f: impl FnOnce() + std::panic::UnwindSafe) -> Option<String> {
    std::panic::catch_unwind(f).err().map(|e| {
        e.downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| e.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "a panic without a message".into())
    })
}
