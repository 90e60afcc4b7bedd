//! The `unispine` binary: parse the command line and hand over to the library.

use clap::Parser;

// The front end: flags, progress bars and printing. It is part of the binary, not of the
// library, so the library (and the Python module built on it) holds no front-end code.
#[allow(clippy::print_stdout, clippy::print_stderr)]
mod cli;

fn main() {
    // Output piped into a reader that stops early (`unispine reproduce --list | head`) ends the
    // process quietly, as for other Unix tools, instead of a panic on the failed write.
    // SAFETY: restoring the default disposition of a signal before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    // A training step at 1024^2 allocates and frees dozens of 4 MiB images. glibc serves
    // blocks above its mmap threshold with fresh mappings: page faults on first touch, and on
    // free an unmap whose TLB shoot-down interrupts the other threads (an expensive exit on a
    // virtual machine). Served from the heap, with freed memory kept for reuse, the 1024^2
    // step's loss stage took about a third of the time and the peak memory did not change
    // (docs/measurements.md). Volumes above 64 MiB still get their own mappings.
    // SAFETY: plain settings calls before any allocation-heavy work or other thread starts.
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 64 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 256 << 20);
    }
    // A usage error (unknown flag, a value that does not parse, such as `--init cube`) names
    // the flag and the value and exits 1 like every other error; help and version exit 0.
    let cli = match cli::Cli::try_parse() {
        Ok(c) => c,
        Err(e) if e.use_stderr() => {
            let _ = e.print();
            std::process::exit(1);
        }
        Err(e) => e.exit(),
    };
    if let Err(e) = cli::run(cli) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
