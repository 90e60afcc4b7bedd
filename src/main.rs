//! The `unispine` binary: parse the command line and hand over to the library.

use clap::Parser;

fn main() {
    let cli = unispine::cli::Cli::parse();
    if let Err(e) = unispine::cli::run(cli) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
