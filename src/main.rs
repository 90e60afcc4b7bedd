//! The `unispine` binary: parse the command line and hand over to the library.

use clap::Parser;

fn main() {
    // Output piped into a reader that stops early (`unispine reproduce --list | head`) ends the
    // process quietly, as for other Unix tools, instead of a panic on the failed write.
    // SAFETY: restoring the default disposition of a signal before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let cli = unispine::cli::Cli::parse();
    if let Err(e) = unispine::cli::run(cli) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
