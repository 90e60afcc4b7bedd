//! Reports: markdown tables and PNG charts, read from run folders.
